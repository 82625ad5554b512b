//! Which kernel family runs a GEMM-shaped op (a matrix product or an implicit-GEMM
//! convolution) and with which variant: the matrix units, the CPU family's subgroup kernels
//! (their rows per workgroup, their operands from storage or texels), or the tiled kernels.

use super::{kernel, u};
use crate::device::DeviceInfo;
use crate::error::{Error, Result};
use crate::kernel_choice::matrix_tile::MatrixTile;
use crate::kernel_choice::plan::GemmFamily;
use crate::recorder::Recorder;
use crate::tensor::{Dtype, Tensor};
use crate::texel_views::{fits, Texels};
use vkdiff_kernels::Variant;

/// What the GEMM-family dispatch needs to know of a matrix product or implicit-GEMM convolution.
pub(super) struct GemmShape {
    pub m: usize,
    pub n: usize,
    pub k: usize,
    pub batch: usize,
    /// Whether the operands are vec4-aligned (sizes and strides), which the subgroup and
    /// cooperative kernels need.
    pub vec4: bool,
    /// Whether A and B can be read in units of 8: the matrix units' 16-byte loads, the CPU
    /// family's eight-half texels.
    pub vec8: bool,
}

/// The kernels of one GEMM-shaped op, one per family.
pub(super) struct GemmKernels {
    pub subgroup: &'static str,
    /// The tiled kernel for vec4-aligned shapes, and the one for any shape (none for
    /// convolutions, which pad their channels onto the vec4 grid).
    pub tiled_v4: &'static str,
    pub tiled: Option<&'static str>,
    pub cooperative: &'static str,
}

impl GemmKernels {
    pub(super) const MATMUL: GemmKernels = GemmKernels {
        subgroup: "gemm_sg",
        tiled_v4: "gemm_tiled_v4",
        tiled: Some("gemm_tiled"),
        cooperative: "gemm_coop",
    };
}

/// Records a GEMM-shaped kernel: the cooperative variant (its tile as `tile` asks) where the
/// context uses the matrix units, the storage is f16 and the shape fits vec4 loads (in units of
/// 8 where it fits those); the subgroup variant where the device prefers it and the shape fits,
/// with more rows per workgroup for taller products; else the tiled one, in vec4 units where
/// the shape fits them and GEGLU is not fused. `params` are the variant parameters all share;
/// bindings are `reads` then `out`.
pub(super) fn dispatch_gemm_family(
    rec: &mut Recorder,
    (names, dtype, params): (GemmKernels, Dtype, &[(&str, u32)]),
    tile: MatrixTile,
    s: &GemmShape,
    reads: &[&Tensor],
    out: &Tensor,
    push: &[u32],
) -> Result<()> {
    let ctx = rec.context().clone();
    rec.count_flops(2.0 * (s.batch * s.m) as f64 * (s.n * s.k) as f64);
    let family = ctx.choices().gemm_family;
    let cooperative =
        ctx.info().cooperative_variant().filter(|_| family == GemmFamily::Cooperative && dtype == Dtype::F16 && s.vec4);
    if let Some(fragment) = cooperative {
        let unit = if s.vec8 { 8 } else { 4 };
        let shared: Vec<(&str, u32)> = params.iter().copied().chain([("UW", unit)]).collect();
        let tile = super::coop_tile::cooperative_tile(&ctx, tile, s, &fragment, names.cooperative, &shared);
        let want: Vec<(&str, u32)> = fragment.params().into_iter().chain(tile.params()).chain(shared).collect();
        let k = kernel(&ctx, names.cooperative, dtype, &want, 4)?;
        let (rows, columns) = tile.size(&fragment);
        return rec.dispatch(&k, reads, &[out], push, [u(s.n.div_ceil(columns)), u(s.m.div_ceil(rows)), u(s.batch)]);
    }
    let width = ctx.info().gemm_subgroup_width().filter(|_| family == GemmFamily::Subgroup && s.vec4);
    if let Some(sg) = width {
        let tm = subgroup_rows(s, sg, ctx.choices().quick_compile);
        let words = ("WD", u32::from(ctx.choices().word_loads));
        let want = |texels: u32| -> Vec<(&str, u32)> {
            [("SG", sg), ("TM", tm), words, ("TB", texels)].into_iter().chain(params.iter().copied()).collect()
        };
        let from_texels = vkdiff_kernels::find(names.subgroup, dtype, &want(1))
            .filter(|v| ctx.choices().texel_reads && texel_operands_fit(ctx.info(), v, reads, s));
        let k = match from_texels {
            Some(variant) => ctx.kernel(variant, 4)?,
            None => kernel(&ctx, names.subgroup, dtype, &want(0), 4)?,
        };
        let columns = u(s.n.div_ceil(8 * sg as usize));
        return rec.dispatch(&k, reads, &[out], push, [columns, u(s.m.div_ceil(tm as usize)), u(s.batch)]);
    }
    if s.vec4 {
        let rh = tiled_row_halves(ctx.info(), s);
        let want: Vec<(&str, u32)> = params.iter().copied().chain([("RH", rh)]).collect();
        if let Some(variant) = vkdiff_kernels::find(names.tiled_v4, dtype, &want) {
            let k = ctx.kernel(variant, 4)?;
            let grid = [u(s.n.div_ceil(128)), u(s.m.div_ceil(64 * rh as usize)), u(s.batch)];
            return rec.dispatch(&k, reads, &[out], push, grid);
        }
    }
    let tiled = names.tiled.ok_or_else(|| {
        Error::Shape(format!("{}: M={} N={} K={} is off the vec4 grid its kernels read", names.tiled_v4, s.m, s.n, s.k))
    })?;
    let k = kernel(&ctx, tiled, dtype, params, 4)?;
    rec.dispatch(&k, reads, &[out], push, [u(s.n.div_ceil(64)), u(s.m.div_ceil(64)), u(s.batch)])
}

/// Whether the device allows texel views of what `variant` reads from texels: B, and A where it
/// reads A so too (TA = 1), whose eight-half texels (f16) also need K and every stride of A and
/// B on multiples of 8 (`s.vec8`).
fn texel_operands_fit(device: &DeviceInfo, variant: &Variant, reads: &[&Tensor], s: &GemmShape) -> bool {
    let texels = Texels::of(variant);
    let a_fits = || fits(device, reads[0], texels) && (texels != Texels::Halves8 || s.vec8);
    fits(device, reads[1], texels) && (variant.param("TA") != Some(1) || a_fits())
}

/// Row halves of the vec4 tiled kernel's 64·RH × 128 tiles: 2 (8×8 outputs an invocation, each
/// staged value used 8 times) where the product still makes 128 such tiles, as the cooperative
/// kernels choose their larger tiles, and the device has the workgroup memory; else 1, so that
/// smaller products spread over more workgroups.
fn tiled_row_halves(device: &DeviceInfo, s: &GemmShape) -> u32 {
    let fills = s.m.div_ceil(128) * s.n.div_ceil(128) * s.batch >= 128;
    if fills && tiled_v4_workgroup_bytes(2) <= device.max_shared_memory {
        2
    } else {
        1
    }
}

/// Workgroup memory of gemm_tiled_v4.wgsl: K-steps of 16 rows of A (16·RH + 1 vec4s of f32) and
/// B (33). At RH = 2 that is 16.5 KiB, past the 16 KiB Vulkan guarantees.
fn tiled_v4_workgroup_bytes(rh: u32) -> u32 {
    16 * (16 * rh + 1 + 33) * 16
}

/// Rows per workgroup of the subgroup kernels: more rows load each B value fewer times. From 512
/// rows (SDXL's 16² level at 512², batch 2) 8 lanes take 64 (fastest on Mesa 22.3's lavapipe) and
/// 16 lanes 128, at two steps a turn (since B and A come from texels: linear rows 1.1–1.2× the
/// 32-row ones; 64 rows ran between). But the JIT time grows about with the square of the rows
/// (measured, 8 lanes: Mesa 25 8 rows 5 s, 16 14 s, 32 57 s, 64 minutes; Mesa 22.3 16 rows 2.5 s,
/// 32 6 s, 64 14–18 s; 16 lanes 32 rows 5 s, 128 about 55 s). So [`small`] products (tiny
/// models, whose products take milliseconds) take 16 rows, or 8 where compiles are `quick`; with
/// `quick` compiles no product takes more than 32.
fn subgroup_rows(s: &GemmShape, sg: u32, quick: bool) -> u32 {
    if small(s.m, s.n, s.k) {
        if quick {
            8
        } else {
            16
        }
    } else if s.m >= 512 && !quick {
        if sg < 16 {
            64
        } else {
            128
        }
    } else if s.m >= 256 {
        32
    } else {
        16
    }
}

/// Whether an m×n×k product is small enough to take the variants that compile quickly: fewer
/// weights than [`SMALL_WEIGHTS`] or at most 8 rows.
pub(super) fn small(m: usize, n: usize, k: usize) -> bool {
    n * k < SMALL_WEIGHTS || m <= 8
}

/// Products with fewer weights than this (2¹⁷: none of SDXL's, CLIP's or the VAE's layers but
/// the first and last convolutions; every layer of the tiny test models) are small enough to
/// take the quickly compiled kernels.
pub(crate) const SMALL_WEIGHTS: usize = 1 << 17;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::device::tests::device;
    use crate::device::DeviceKind;

    #[test]
    fn the_tiled_kernel_takes_its_tall_tiles_where_they_fill_and_fit() {
        let shape = |m, n| GemmShape { m, n, k: 640, batch: 1, vec4: true, vec8: true };
        let mut gpu = device(0, DeviceKind::Discrete, true);
        assert_eq!(tiled_row_halves(&gpu, &shape(2048, 1024)), 2, "128 tiles of 128×128");
        assert_eq!(tiled_row_halves(&gpu, &shape(2048, 896)), 1, "112 tiles");
        gpu.max_shared_memory = 16384;
        assert_eq!(tiled_row_halves(&gpu, &shape(8192, 1280)), 1, "16 KiB of workgroup memory");
    }
}
