//! Which kernels a context on a device starts with, and why: decided here once, from what the
//! device reports and the [`Settings`]. [`crate::Context::new`] starts from it and `vkdiff
//! devices` prints it, so what the command says is what a run does.

use crate::device::{DeviceInfo, DeviceKind};
use crate::kernel_choice::matrix_tile::{unbuilt_tile_note, MatrixTile};
use crate::kernel_choice::matrix_units::{built_cooperative_variants, Fragment};
use crate::kernel_choice::probe::ProbeChoice;
use crate::settings::{CooperativeSetting, Settings};
use std::fmt;

/// Which family of GEMM/convolution kernels a context uses (see kernels/src/spec.rs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GemmFamily {
    /// One subgroup per workgroup, A shared by shuffles: fast where loads are scalarised (CPUs).
    Subgroup,
    /// Shared-memory tiles: the GPU kernel, and the fallback for shapes `Subgroup` cannot take.
    Tiled,
    /// The device's matrix units (`VK_KHR_cooperative_matrix`) for f16 products; f32 products,
    /// and devices whose units fit no variant, take `Tiled`.
    Cooperative,
}

/// How much faster the tiled kernels must be to displace the matrix units, so that a device
/// near a tie keeps one choice from run to run (and its images their bits).
pub const MARGIN: f64 = 1.25;

/// The kernels a context on one device starts with.
#[derive(Clone, Debug, PartialEq)]
pub struct KernelPlan {
    /// Whether the device runs as a discrete GPU would (`VKDIFF_GPU_PATHS`).
    pub gpu_paths: bool,
    pub gemm: GemmFamily,
    /// The subgroup-register kernels' width, where `gemm` is [`GemmFamily::Subgroup`].
    pub subgroup_width: Option<u32>,
    /// The matrix units' fragment, where `gemm` is [`GemmFamily::Cooperative`].
    pub fragment: Option<Fragment>,
    /// Why `gemm` is not the matrix units on a device that lists some.
    pub no_units: Option<String>,
    /// Whether a product is timed on the matrix units and on the tiled kernels as a context
    /// starts, and the units kept only where both agree and the tiled kernels are not
    /// [`MARGIN`] faster.
    pub trial: bool,
    pub tile: MatrixTile,
    /// Where `tile` asks for an eight-subgroup tile not built for the fragment.
    pub tile_note: Option<String>,
    /// Attention on the subgroup-register kernels (CPU devices) rather than the GPU's.
    pub subgroup_attention: bool,
    /// Whether the device's workgroup memory holds the register-blocked attention tiles.
    pub tiled_attention: bool,
    /// VK_NV_cooperative_matrix2's probes for attention, the linear layers and the convolution.
    pub probes: [ProbeChoice; 3],
    /// Small products on the quickly compiled variants.
    pub quick_compile: bool,
    /// Whether the kernels are compiled at their first dispatch (lavapipe).
    pub compiled_at_first_use: bool,
    /// Each shape's kernels timed and the fastest taken (`VKDIFF_TUNE`).
    pub tune: bool,
    /// Whether the subgroup-register kernels read their operands as 64-bit words (WD = 1 in
    /// kernels/src/spec.rs): on lavapipe that `loads_lane_by_lane`, whose every storage-buffer
    /// component is a loop of branches over the lanes, so wider components make fewer loops.
    pub word_loads: bool,
    /// Whether the subgroup-register kernels read B, and A of the plain products (TA), through
    /// texel views (TB = 1): on lavapipe that `loads_lane_by_lane`, which fetches texels for all
    /// lanes at once.
    pub texel_reads: bool,
    /// Whether 3×3 convolutions of stride 1 (of 2¹⁷ weights or more, `Choices::winograd_from`)
    /// run as Winograd's F(2×2, 3×3): the CPU family (2.25× less matrix work;
    /// `VKDIFF_WINOGRAD=0` runs them direct). GPUs keep the direct convolution, measured on none.
    pub winograd: bool,
    /// Whether the CPU could give lavapipe wider vectors than it has (AVX-512, no width chosen,
    /// a release whose UNet ran faster at 16 lanes: `wider_vectors_ran_faster`).
    pub wider_vectors: bool,
    /// Whether the kernels' shuffles from constant lanes are written as broadcasts
    /// ([`DeviceInfo::shuffles_loop_over_lanes`]).
    pub broadcasts: bool,
}

impl KernelPlan {
    /// The plan for a context on `info` under `settings`.
    pub fn for_device(info: &DeviceInfo, settings: &Settings) -> KernelPlan {
        let gpu_paths = settings.gpu_paths;
        let cpu = !gpu_paths && info.kind == DeviceKind::Cpu;
        let units = info.cooperative_variant();
        let allowed = settings.cooperative != CooperativeSetting::Never;
        let subgroup_width = cpu.then(|| info.gemm_subgroup_width()).flatten();
        let gemm = if subgroup_width.is_some() {
            GemmFamily::Subgroup
        } else if !cpu && units.is_some() && allowed {
            GemmFamily::Cooperative
        } else {
            GemmFamily::Tiled
        };
        let fragment = units.filter(|_| gemm == GemmFamily::Cooperative);
        let no_units = match (&info.matrix_shapes[..], units) {
            ([], _) => None,
            (_, None) if !info.cooperative_features => {
                Some("no cooperativeMatrix or vulkanMemoryModel feature".to_string())
            }
            (_, None) => Some(format!(
                "no vkdiff variant fits them (f16·f16+f32 at subgroup scope, {})",
                built_cooperative_variants()
            )),
            (_, Some(_)) if cpu => Some("a CPU device takes the subgroup-register kernels".into()),
            (_, Some(_)) if !allowed => Some("VKDIFF_COOPERATIVE=0".into()),
            (_, Some(_)) => None,
        };
        KernelPlan {
            gpu_paths,
            gemm,
            subgroup_width,
            fragment,
            no_units,
            trial: fragment.is_some() && settings.cooperative == CooperativeSetting::Trial,
            tile: settings.matrix_tile,
            tile_note: unbuilt_tile_note(settings.matrix_tile, &info.name, fragment),
            subgroup_attention: info.subgroup_attention(gpu_paths),
            tiled_attention: info.holds_tiled_attention(),
            probes: [settings.attention, settings.linear, settings.conv],
            quick_compile: !gpu_paths && settings.quick_compile.unwrap_or(prefers_quick_compiles(info)),
            compiled_at_first_use: info.lavapipe_mesa.is_some(),
            tune: settings.tune,
            word_loads: subgroup_width.is_some() && loads_lane_by_lane(info) && info.can_read_words(),
            texel_reads: subgroup_width.is_some()
                && loads_lane_by_lane(info)
                && info.reads_texels()
                && !wrong_texels_at_16_lanes(info),
            winograd: gemm == GemmFamily::Subgroup && settings.winograd,
            broadcasts: info.shuffles_loop_over_lanes(),
            wider_vectors: crate::kernel_choice::cpu_vectors::wider_vectors_ran_faster(info.lavapipe_mesa)
                && crate::kernel_choice::cpu_vectors::wider_lavapipe_vectors_available(settings),
        }
    }

    /// The GEMM and convolution kernels, in words.
    fn products(&self) -> String {
        match (self.gemm, self.fragment) {
            (GemmFamily::Subgroup, _) => {
                let wide = self.word_loads
                    && self.subgroup_width.is_some_and(|lanes| lanes <= vkdiff_kernels::WIDEST_64_BIT_WORDS);
                let words = if wide { ", operands in 64-bit words" } else { ", operands in 32-bit words" };
                let texels = if self.texel_reads { ", operands from texels" } else { "" };
                let winograd = if self.winograd { ", 3×3 convolutions by Winograd F(2×2, 3×3)" } else { "" };
                let broadcasts = if self.broadcasts { ", broadcasts (not shuffles)" } else { "" };
                let lanes = self.subgroup_width.unwrap_or_default();
                format!("subgroup-register, {lanes} lanes (CPU){words}{texels}{broadcasts}{winograd}")
            }
            (GemmFamily::Cooperative, Some(f)) => {
                let trial = match self.trial {
                    true => format!(
                        ", unless a product timed on them as vkdiff starts differs from the tiled kernels' or takes \
                         over {MARGIN}× their time"
                    ),
                    false => String::new(),
                };
                let tile = match self.tile {
                    MatrixTile::Auto => String::new(),
                    tile => format!(", VKDIFF_MATRIX_TILE={}", tile.name()),
                };
                format!(
                    "matrix units, {} f16→f32 fragments, {} lanes{}{trial}{tile} (f32 products: shared-memory tiles)",
                    f.shape(),
                    f.lanes,
                    if f.flexible { " through flexible dimensions" } else { "" }
                )
            }
            _ => "shared-memory tiles (GPU)".into(),
        }
    }

    /// The attention kernels, in words.
    fn attention(&self) -> String {
        let tiles = if self.tiled_attention { "register-blocked tiles for heads up to 64, else " } else { "" };
        let flash = if self.subgroup_attention {
            "subgroup-register (CPU)".to_string()
        } else if self.gemm == GemmFamily::Cooperative {
            format!("matrix units for f16 heads up to 64, else {tiles}query rows per invocation (GPU)")
        } else {
            format!("{tiles}query rows per invocation (GPU)")
        };
        format!("{flash}; heads over 128 (the VAE's): products around a row softmax, f16 heads widened to f32 for them")
    }
}

impl fmt::Display for KernelPlan {
    /// One line per part: `GEMM/conv kernels: …`, `attention: …`, then the notes that apply.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "GEMM/conv kernels: {}", self.products())?;
        if let Some(why) = &self.no_units {
            write!(f, " (not the matrix units: {why})")?;
        }
        write!(f, "\nattention: {}", self.attention())?;
        let probes: Vec<&str> = ["VKDIFF_ATTENTION", "VKDIFF_LINEAR", "VKDIFF_CONV"]
            .iter()
            .zip(self.probes)
            .filter(|(_, p)| *p == ProbeChoice::Matrix2)
            .map(|(name, _)| *name)
            .collect();
        if !probes.is_empty() {
            write!(f, "\nVK_NV_cooperative_matrix2's probes where they fit: {}=cm2", probes.join("=cm2, "))?;
        }
        if self.compiled_at_first_use {
            let quick = if self.quick_compile { ", small products on the quickly compiled variants" } else { "" };
            write!(f, "\nkernels compiled at first use{quick}")?;
        }
        if self.tune {
            write!(f, "\nVKDIFF_TUNE=1: each shape's kernels timed on the device, the fastest taken")?;
        }
        if self.gpu_paths {
            write!(f, "\nVKDIFF_GPU_PATHS=1: device memory through staging, GPU kernels")?;
        }
        if let Some(note) = &self.tile_note {
            write!(f, "\n{note}")?;
        }
        if self.wider_vectors {
            write!(
                f,
                "\nthis CPU has AVX-512: LP_NATIVE_VECTOR_WIDTH=512 gives lavapipe 16-lane kernels (faster on an AMD \
                 EPYC once a first run has compiled them, for minutes; slower on an Intel Xeon: BENCHMARKS.md)"
            )?;
        }
        Ok(())
    }
}

/// Whether small products should take the quickly compiled variants (and large ones no 64-row
/// tile nor fused GEGLU): lavapipe after Mesa 22, whose JIT takes minutes for the larger ones;
/// but not from Mesa 26 at 16 lanes, a width the user chose for speed, where the fast variants
/// ran the SDXL UNet 1.2× faster for about 9 minutes more of JIT, once (Mesa's shader cache
/// keeps it; docs/benchmark-log.md). Mesa 25 at 16 lanes keeps them: its 128-row tiles took
/// longer to compile than that for the linear rows alone.
fn prefers_quick_compiles(info: &DeviceInfo) -> bool {
    info.lavapipe_mesa.is_some_and(|(major, _)| major > 22 && !(major >= 26 && info.subgroup_size == 16))
}

/// Whether the device is lavapipe before Mesa 26, whose storage loads are loops of branches over
/// the lanes: there the 64-bit words and B's texels ran the f16 linear rows 1.3× (Mesa 22.3) and
/// 1.4× (Mesa 25.0) faster; Mesa 26.1 gathers each lane without a loop, and there they ran slower
/// (docs/benchmark-log.md). Mesa 23, 24 and 25.1–25.3 were not measured.
fn loads_lane_by_lane(info: &DeviceInfo) -> bool {
    info.lavapipe_mesa.is_some_and(|(major, _)| major < 26)
}

/// Mesa 25.0 at 16 lanes returned wrong products from texels (the GEMM's tests failed against
/// f64; from storage they pass, 2026-12-06), so at 16 lanes only Mesa 22 reads texels.
fn wrong_texels_at_16_lanes(info: &DeviceInfo) -> bool {
    info.subgroup_size > 8 && info.lavapipe_mesa.is_some_and(|(major, _)| major > 22)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::device::tests::device;
    use crate::kernel_choice::matrix_units::MatrixShape;

    /// An NVIDIA-like GPU whose matrix units take vkdiff's 16×16×16 variant at 32 lanes.
    fn gpu_with_units() -> DeviceInfo {
        let mut d = device(0, DeviceKind::Discrete, true);
        let types = ["f16", "f16", "f32", "f32"];
        d.matrix_shapes =
            vec![MatrixShape { m: 16, n: 16, k: 16, types, subgroup_scope: true, workgroup_invocations: 0 }];
        d.cooperative_features = true;
        d.subgroup_size = 32;
        d
    }

    #[test]
    fn a_gpu_with_units_tries_them_unless_the_settings_say_otherwise() {
        let d = gpu_with_units();
        let plan = KernelPlan::for_device(&d, &Settings::default());
        assert_eq!((plan.gemm, plan.trial, plan.no_units.as_deref()), (GemmFamily::Cooperative, true, None));
        assert!(plan.to_string().contains("matrix units, 16×16×16 f16→f32 fragments, 32 lanes, unless"), "{plan}");
        let always = Settings { cooperative: CooperativeSetting::Always, ..Settings::default() };
        assert!(!KernelPlan::for_device(&d, &always).trial);
        let never = Settings { cooperative: CooperativeSetting::Never, ..Settings::default() };
        let plan = KernelPlan::for_device(&d, &never);
        assert_eq!((plan.gemm, plan.fragment), (GemmFamily::Tiled, None));
        assert!(plan.to_string().contains("shared-memory tiles (GPU) (not the matrix units: VKDIFF_COOPERATIVE=0)"));
    }

    #[test]
    fn a_cpu_takes_the_subgroup_kernels_and_its_gpu_paths_the_gpus() {
        let mut d = device(0, DeviceKind::Cpu, true);
        d.subgroup_size = 8;
        d.lavapipe_mesa = Some((25, 0));
        let plan = KernelPlan::for_device(&d, &Settings::default());
        assert_eq!((plan.gemm, plan.subgroup_width, plan.subgroup_attention), (GemmFamily::Subgroup, Some(8), true));
        assert!(plan.quick_compile, "lavapipe after Mesa 22 compiles slowly");
        let slow = Settings { quick_compile: Some(false), ..Settings::default() };
        assert!(!KernelPlan::for_device(&d, &slow).quick_compile);
        // Mesa 26 at 16 lanes takes the fast variants, compiled once; Mesa 22 compiles quickly.
        for (release, lanes, quick) in
            [((25, 0), 16, true), ((26, 1), 16, false), ((26, 1), 8, true), ((22, 3), 16, false)]
        {
            let at = DeviceInfo { lavapipe_mesa: Some(release), subgroup_size: lanes, ..d.clone() };
            assert_eq!(
                KernelPlan::for_device(&at, &Settings::default()).quick_compile,
                quick,
                "{release:?}, {lanes} lanes"
            );
        }
        let gpu = KernelPlan::for_device(&d, &Settings { gpu_paths: true, ..Settings::default() });
        assert_eq!((gpu.gemm, gpu.subgroup_attention, gpu.quick_compile), (GemmFamily::Tiled, false, false));
        assert!(gpu.to_string().contains("VKDIFF_GPU_PATHS=1"), "{gpu}");
    }

    #[test]
    fn lavapipe_after_mesa_22_at_16_lanes_takes_broadcasts() {
        let mut d = device(0, DeviceKind::Cpu, true);
        let takes = |d: &DeviceInfo| {
            let plan = KernelPlan::for_device(d, &Settings::default());
            assert_eq!(plan.broadcasts, plan.to_string().contains("broadcasts (not shuffles)"), "{plan}");
            plan.broadcasts
        };
        d.subgroup_size = 16;
        d.lavapipe_mesa = Some((22, 3));
        assert!(!takes(&d), "Mesa 22's shuffle from a constant lane is one vector shuffle");
        for release in [(25, 0), (26, 1)] {
            d.lavapipe_mesa = Some(release);
            assert!(takes(&d), "Mesa {release:?} builds a 16-lane shuffle as a loop");
        }
        d.subgroup_size = 8;
        assert!(!takes(&d), "8 lanes' shuffle is one vpermd");
        d.subgroup_size = 16;
        d.lavapipe_mesa = None;
        assert!(!takes(&d), "other drivers keep naga's shuffles");
    }

    #[test]
    fn lavapipe_before_mesa_26_reads_words_and_only_with_the_integers_they_need() {
        let mut d = device(0, DeviceKind::Cpu, true);
        d.subgroup_size = 8;
        let words = |d: &DeviceInfo| KernelPlan::for_device(d, &Settings::default()).word_loads;
        d.lavapipe_mesa = Some((22, 3));
        assert!(words(&d));
        let plan = KernelPlan::for_device(&d, &Settings::default()).to_string();
        assert!(plan.contains("8 lanes (CPU), operands in 64-bit words"), "{plan}");
        d.lavapipe_mesa = Some((25, 0));
        assert!(words(&d), "Mesa 25.0 loads lane by lane too");
        d.lavapipe_mesa = Some((26, 1));
        assert!(!words(&d), "Mesa 26.1 gathers 32-bit words faster than 64-bit ones");
        let plan = KernelPlan::for_device(&d, &Settings::default()).to_string();
        assert!(plan.contains("8 lanes (CPU), operands in 32-bit words"), "{plan}");
        d.lavapipe_mesa = None;
        assert!(!words(&d), "another CPU driver reads 32-bit words");
        d.lavapipe_mesa = Some((22, 3));
        d.shader_int64 = false;
        assert!(!words(&d), "8 lanes' words are 64-bit integers");
        d.subgroup_size = 16;
        assert!(words(&d), "16 lanes read 32-bit words");
        let plan = KernelPlan::for_device(&d, &Settings::default()).to_string();
        assert!(plan.contains("16 lanes (CPU), operands in 32-bit words"), "{plan}");
        let gpu_paths = Settings { gpu_paths: true, ..Settings::default() };
        assert!(!KernelPlan::for_device(&d, &gpu_paths).word_loads);
    }

    #[test]
    fn lavapipe_before_mesa_26_reads_operands_from_texels_and_only_where_it_fetches_them() {
        let mut d = device(0, DeviceKind::Cpu, true);
        d.subgroup_size = 8;
        d.texel_fetch = Some(crate::texel_views::TexelLimits { max_elements: 1 << 27, offset_alignment: 16 });
        let texels = |d: &DeviceInfo| KernelPlan::for_device(d, &Settings::default()).texel_reads;
        d.lavapipe_mesa = Some((22, 3));
        assert!(texels(&d));
        let plan = KernelPlan::for_device(&d, &Settings::default()).to_string();
        assert!(plan.contains("8 lanes (CPU), operands in 64-bit words, operands from texels"), "{plan}");
        d.subgroup_size = 16;
        assert!(texels(&d), "every width fetches texels");
        d.lavapipe_mesa = Some((25, 0));
        assert!(!texels(&d), "Mesa 25.0 returned wrong products from texels at 16 lanes");
        d.subgroup_size = 8;
        assert!(texels(&d), "Mesa 25.0 loads storage lane by lane too");
        d.lavapipe_mesa = Some((26, 1));
        assert!(!texels(&d), "Mesa 26.1 ran f16 products slower from texels");
        d.lavapipe_mesa = None;
        assert!(!texels(&d), "another CPU driver reads storage");
        d.lavapipe_mesa = Some((22, 3));
        let gpu_paths = Settings { gpu_paths: true, ..Settings::default() };
        assert!(!KernelPlan::for_device(&d, &gpu_paths).texel_reads);
        d.texel_fetch = None;
        assert!(!texels(&d), "a device that cannot fetch both formats reads storage");
    }

    #[test]
    fn the_cpu_family_takes_winograd_convolutions_unless_told_not_to() {
        let mut d = device(0, DeviceKind::Cpu, true);
        d.subgroup_size = 8;
        d.lavapipe_mesa = Some((22, 3));
        let plan = KernelPlan::for_device(&d, &Settings::default());
        assert!(plan.winograd);
        assert!(plan.to_string().contains("3×3 convolutions by Winograd F(2×2, 3×3)"), "{plan}");
        let direct = Settings { winograd: false, ..Settings::default() };
        assert!(!KernelPlan::for_device(&d, &direct).winograd);
        let gpu_paths = Settings { gpu_paths: true, ..Settings::default() };
        assert!(!KernelPlan::for_device(&d, &gpu_paths).winograd, "the GPU kernels convolve direct");
        assert!(!KernelPlan::for_device(&device(0, DeviceKind::Discrete, true), &Settings::default()).winograd);
    }
}
