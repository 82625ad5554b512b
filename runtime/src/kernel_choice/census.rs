//! `vkdiff devices --compile`: every kernel variant a device's selection can pick, compiled by its
//! driver one at a time, with what the driver reports of each (registers, spills, instruction
//! counts). A driver compiles a kernel when its pipeline is created, so this finds a variant that
//! a vendor's compiler refuses, or that spills registers to memory, before any run does. Under
//! Mesa's drm-shim (a GPU that compiles for real and executes nothing) it compiles for AMD's and
//! NVIDIA's GPUs on a machine without one.

use crate::context::Context;
use crate::device::{DeviceInfo, DeviceKind};
use crate::error::Result;
use crate::kernel_choice::plan::KernelPlan;
use crate::pipeline::create_kernel;
use crate::pipeline_stats::{memory_spills, Statistics};
use crate::settings::Settings;
use std::time::Instant;
use vkdiff_kernels::{Dtype, Variant, VARIANTS};

/// Storage bindings of the census's pipeline layout: the most any kernel declares (a layout may
/// hold bindings a kernel does not use).
const BINDINGS: u32 = 5;

/// One variant as the driver compiled it.
pub struct CompiledKernel {
    pub variant: &'static Variant,
    /// Pipeline creation, the driver's compiler included.
    pub seconds: f64,
    /// Each executable's statistics; empty where the device reports none.
    pub statistics: Vec<Statistics>,
}

impl CompiledKernel {
    /// Bytes a lane spills to memory, summed over the executables, where the driver says.
    pub fn memory_spills(&self) -> Option<u64> {
        self.statistics.iter().filter_map(memory_spills).reduce(|a, b| a + b)
    }
}

/// The variants a context on this device can pick, as `ops` chooses them: those written for no
/// particular subgroup width (element-wise, norms, the tiled GEMMs and attention kernels), in
/// f16 only where the device runs f16; then on CPU devices (lavapipe, without
/// `VKDIFF_GPU_PATHS`) the subgroup-register variants of its width, and on GPUs the matrix-unit
/// variants of the fragment and width it takes; and the `VK_NV_cooperative_matrix2` probe's
/// tiles the device runs (`bench kernels` takes them).
pub fn selectable_variants(info: &DeviceInfo, settings: &Settings) -> Vec<&'static Variant> {
    let gpu_paths = settings.gpu_paths;
    let fragment = KernelPlan::for_device(info, settings).fragment;
    let subgroup_width = (!gpu_paths && info.kind == DeviceKind::Cpu).then_some(info.subgroup_size);
    let matrix2_tiles = info.matrix2_tiles();
    VARIANTS
        .iter()
        .filter(|v| v.dtype == Dtype::F32 || info.supports_f16())
        .filter(|v| match (v.param("SG"), v.param("FM")) {
            _ if v.kernel.ends_with("_cm2") => matrix2_tiles
                .iter()
                .any(|t| t.probe.kernel() == v.kernel && t.params().iter().all(|(n, x)| v.param(n) == Some(*x))),
            (None, _) => true,
            (Some(_), Some(_)) => fragment.is_some_and(|f| f.params().iter().all(|(n, x)| v.param(n) == Some(*x))),
            (Some(sg), None) => subgroup_width == Some(sg),
        })
        .collect()
}

impl Context {
    /// Compiles `variant` for this device and reads what the driver reports of it; the
    /// pipeline is not kept. An error is the driver's refusal.
    pub fn compile_for_census(&self, variant: &'static Variant) -> Result<CompiledKernel> {
        let start = Instant::now();
        let (kernel, reported) = create_kernel(&self.shared.device, self.compile_options(), variant, BINDINGS)?;
        let seconds = start.elapsed().as_secs_f64();
        // SAFETY: the pipeline was never used.
        unsafe { kernel.destroy(&self.shared.device) };
        let statistics = match reported {
            Some(Ok(each)) => each,
            Some(Err(why)) => {
                eprintln!("vkdiff: {}: {why}", crate::pipeline_stats::variant_label(variant));
                Vec::new()
            }
            None => Vec::new(),
        };
        Ok(CompiledKernel { variant, seconds, statistics })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::device::tests::device;
    use crate::MatrixShape;

    fn gpu() -> DeviceInfo {
        device(0, DeviceKind::Discrete, true)
    }

    fn names(variants: &[&Variant]) -> Vec<String> {
        variants.iter().map(|v| crate::pipeline_stats::variant_label(v)).collect()
    }

    #[test]
    fn a_cpu_device_takes_its_width_and_no_matrix_units() {
        let info = DeviceInfo { subgroup_size: 8, ..device(0, DeviceKind::Cpu, true) };
        let picked = names(&selectable_variants(&info, &Settings::default()));
        assert!(picked.iter().any(|n| n.starts_with("gemm_sg F32 SG=8 ")));
        assert!(!picked.iter().any(|n| n.contains(" SG=4 ") || n.contains(" SG=16 ")), "{picked:?}");
        assert!(!picked.iter().any(|n| n.contains("_coop")));
        assert!(picked.iter().any(|n| n.starts_with("gemm_tiled_v4 ")), "the tiled GEMM takes off-grid shapes");
    }

    #[test]
    fn a_gpu_takes_no_subgroup_register_variant() {
        let picked = names(&selectable_variants(&gpu(), &Settings::default()));
        assert!(!picked.iter().any(|n| n.contains(" SG=")), "{picked:?}");
        assert!(picked.iter().any(|n| n.starts_with("attention_rows ")));
        assert!(picked.iter().any(|n| n.starts_with("geglu_v4 F16")));
        let no_f16 = DeviceInfo { shader_f16: false, ..gpu() };
        assert!(!names(&selectable_variants(&no_f16, &Settings::default())).iter().any(|n| n.contains(" F16")));
    }

    #[test]
    fn a_gpu_with_matrix_units_takes_its_fragment_at_its_width() {
        let shape = MatrixShape {
            m: 16,
            n: 16,
            k: 16,
            types: ["f16", "f16", "f32", "f32"],
            subgroup_scope: true,
            workgroup_invocations: 0,
        };
        let info = DeviceInfo {
            matrix_shapes: vec![shape],
            cooperative_features: true,
            subgroup_size_range: Some((32, 64)),
            ..gpu()
        };
        let picked = names(&selectable_variants(&info, &Settings::default()));
        let coop: Vec<&String> = picked.iter().filter(|n| n.contains("_coop") || n.contains("coop_")).collect();
        assert!(!coop.is_empty());
        assert!(coop.iter().all(|n| n.contains(" FM=16 FN=16 FK=16 SG=32")), "{coop:?}");
        for kernel in ["gemm_coop", "conv_coop", "attention_coop", "coop_ceiling"] {
            assert!(coop.iter().any(|n| n.starts_with(kernel)), "{kernel}");
        }
        assert!(!picked.iter().any(|n| n.starts_with("gemm_sg")));
        assert!(!picked.iter().any(|n| n.starts_with("gemm_cm2")), "no VK_NV_cooperative_matrix2 offered");
        // A driver of workgroup scope at 256 invocations, its per-element operations and
        // conversions, adds the linear and convolution probes' tiles of that size, nothing else
        // (attention's needs the reductions too).
        let granularity =
            MatrixShape { subgroup_scope: false, workgroup_invocations: 256, ..info.matrix_shapes[0].clone() };
        let cm2 = DeviceInfo {
            flexible_shapes: vec![granularity],
            cooperative_matrix2: vec![
                "workgroup scope",
                "flexible dimensions",
                "conversions",
                "per-element operations",
            ],
            ..info
        };
        let with_probe = names(&selectable_variants(&cm2, &Settings::default()));
        let probe: Vec<&String> = with_probe.iter().filter(|n| n.contains("_cm2")).collect();
        assert!(probe.iter().all(|n| n.contains(" WS=1 WG=256")), "{probe:?}");
        for kernel in ["gemm_cm2", "conv_cm2"] {
            assert_eq!(probe.iter().filter(|n| n.starts_with(kernel)).count(), 2, "{kernel}: {probe:?}");
        }
        assert_eq!(with_probe.len(), picked.len() + probe.len());
    }
}
