//! Normalisations and softmax over NHWC / row-major tensors, accumulated in f32.

use super::bands::{bands, elem, fit, row_view, rows_per_band};
use super::{dispatch_flat, f, kernel, rows_of, same_dtype, u, unit_kernel};
use crate::context::Context;
use crate::device::DeviceKind;
use crate::error::{ensure, Result};
use crate::recorder::Recorder;
use crate::tensor::Dtype;
use crate::tensor::Tensor;

/// GroupNorm of x[B, ..., C] (channels last) with `groups` groups, optionally followed by SiLU.
pub fn group_norm(
    rec: &mut Recorder,
    x: &Tensor,
    gamma: &Tensor,
    beta: &Tensor,
    out: &Tensor,
    groups: usize,
    eps: f32,
    silu: bool,
) -> Result<()> {
    let dtype = same_dtype(rec.context(), "group_norm", &[x, gamma, beta, out])?;
    ensure(x.shape().len() >= 2, || format!("group_norm: want [B, ..., C], got {:?}", x.shape()))?;
    let (b, c) = (x.shape()[0], *x.shape().last().unwrap());
    ensure(groups > 0 && c % groups == 0, || format!("group_norm: {c} channels do not split into {groups} groups"))?;
    ensure(gamma.numel() == c && beta.numel() == c && out.shape() == x.shape(), || {
        "group_norm: affine or output shape mismatch".into()
    })?;
    let hw = x.numel() / (b * c);
    if !fit(rec.context(), &[x, out]) {
        return group_norm_banded(rec, [x, gamma, beta, out], (b, hw, c), groups, eps, silu);
    }
    if let Some(band) = gpu_band(rec.context(), groups, hw) {
        return group_norm_split(rec, [x, gamma, beta, out], (b, hw, c), groups, (eps, silu), band);
    }
    let (k, unit) = unit_kernel(rec.context(), &GROUP_NORM, dtype, &[], 4, &[c / groups])?;
    let push = [u(hw), u(c / unit), u(groups), f(eps), silu as u32];
    rec.dispatch(&k, &[x, gamma, beta], &[out], &push, [u(groups), u(b), 1])
}

/// GroupNorm's kernels, each as two or four channels a step where a group's channels allow
/// (SDXL: 10, 20 and 40 a group) and as one (kernels/wgsl/unit_1.wgsl).
const GROUP_NORM: [(&str, usize); 3] = [("group_norm_v4", 4), ("group_norm_v2", 2), ("group_norm", 1)];
const GROUP_NORM_STATS: [(&str, usize); 3] =
    [("group_norm_stats_v4", 4), ("group_norm_stats_v2", 2), ("group_norm_stats", 1)];
const GROUP_NORM_APPLY: [(&str, usize); 3] =
    [("group_norm_apply_v4", 4), ("group_norm_apply_v2", 2), ("group_norm_apply", 1)];

/// Pixels per band on a GPU, where an image splits into more than one: enough bands for about
/// 1024 workgroups of (group, band) per image, each band at least 64 pixels. One workgroup per
/// group (as on CPU devices) is 64 in all for SDXL's 32 groups and a CFG batch, a fraction of a
/// GPU (GroupNorm ran at 40 GB/s on an H200). The bands depend on the image alone, never on the
/// batch or the binding limit, so an image's result is the same bits in any batch.
fn gpu_band(ctx: &Context, groups: usize, hw: usize) -> Option<usize> {
    let parts = 1024usize.div_ceil(groups).min(hw / 64);
    let gpu = ctx.choices().gpu_paths || ctx.info().kind != DeviceKind::Cpu;
    (gpu && parts > 1).then(|| hw.div_ceil(parts))
}

/// GroupNorm of a tensor in one binding, each image split into bands of `band` pixels: the
/// bands' statistics in one dispatch, then every band normalised with its image's merged ones.
fn group_norm_split(
    rec: &mut Recorder,
    [x, gamma, beta, out]: [&Tensor; 4],
    (b, hw, c): (usize, usize, usize),
    groups: usize,
    (eps, silu): (f32, bool),
    band: usize,
) -> Result<()> {
    let ctx = rec.context().clone();
    let parts = hw.div_ceil(band);
    let stats = ctx.zeros(&[b * parts * groups * 3], Dtype::F32)?;
    let grid = [u(groups), u(parts), u(b)];
    let (k, unit) = unit_kernel(&ctx, &GROUP_NORM_STATS, x.dtype(), &[], 2, &[c / groups])?;
    rec.dispatch(&k, &[x], &[&stats], &[u(hw), u(c / unit), u(groups), 0, u(band), u(parts)], grid)?;
    let (k, unit) = unit_kernel(&ctx, &GROUP_NORM_APPLY, x.dtype(), &[], 5, &[c / groups])?;
    let push = [u(hw), u(c / unit), u(groups), f(eps), silu as u32, 0, u(parts), u(band)];
    rec.dispatch(&k, &[x, gamma, beta, &stats], &[out], &push, grid)
}

/// GroupNorm over bands of pixels: every band's statistics first, then each band normalised
/// with its image's merged statistics, so the result equals the whole-tensor one.
fn group_norm_banded(
    rec: &mut Recorder,
    [x, gamma, beta, out]: [&Tensor; 4],
    (b, hw, c): (usize, usize, usize),
    groups: usize,
    eps: f32,
    silu: bool,
) -> Result<()> {
    let ctx = rec.context().clone();
    let per = rows_per_band(&ctx, "group_norm", &[c * elem(x)], 0, 64)?;
    // A GPU's own bands where they fit the binding, so the result is the split path's bits.
    let per = gpu_band(&ctx, groups, hw).filter(|&band| band <= per).unwrap_or(per);
    let parts = hw.div_ceil(per);
    let stats = ctx.zeros(&[b * parts * groups * 3], Dtype::F32)?;
    let pixels = |image: usize, band: &std::ops::Range<usize>| image * hw + band.start..image * hw + band.end;
    let (k, unit) = unit_kernel(&ctx, &GROUP_NORM_STATS, x.dtype(), &[], 2, &[c / groups])?;
    for image in 0..b {
        for (i, band) in bands(hw, per).enumerate() {
            let push = [u(band.len()), u(c / unit), u(groups), u(image * parts + i), u(band.len()), 1];
            rec.dispatch(&k, &[&row_view(x, c, pixels(image, &band))?], &[&stats], &push, [u(groups), 1, 1])?;
        }
    }
    let (k, unit) = unit_kernel(&ctx, &GROUP_NORM_APPLY, x.dtype(), &[], 5, &[c / groups])?;
    for image in 0..b {
        for band in bands(hw, per) {
            let (n, c_units) = (u(band.len()), u(c / unit));
            let push = [n, c_units, u(groups), f(eps), silu as u32, u(image * parts), u(parts), n];
            let (xs, ys) = (row_view(x, c, pixels(image, &band))?, row_view(out, c, pixels(image, &band))?);
            rec.dispatch(&k, &[&xs, gamma, beta, &stats], &[&ys], &push, [u(groups), 1, 1])?;
        }
    }
    Ok(())
}

/// LayerNorm over the last dimension with affine weight and bias.
pub fn layer_norm(rec: &mut Recorder, x: &Tensor, gamma: &Tensor, beta: &Tensor, out: &Tensor, eps: f32) -> Result<()> {
    let dtype = same_dtype(rec.context(), "layer_norm", &[x, gamma, beta, out])?;
    let (rows, c) = rows_of(x, "layer_norm")?;
    ensure(gamma.numel() == c && beta.numel() == c && out.shape() == x.shape(), || {
        "layer_norm: affine or output shape mismatch".into()
    })?;
    // Four values a load where C allows (every SDXL and CLIP width).
    let lanes = if c.is_multiple_of(4) { 4 } else { 1 };
    let k = kernel(rec.context(), if lanes == 4 { "layer_norm_v4" } else { "layer_norm" }, dtype, &[], 4)?;
    for band in row_bands(rec, "layer_norm", x, out, rows, c)? {
        let (xs, ys) = (row_view(x, c, band.clone())?, row_view(out, c, band.clone())?);
        dispatch_flat(rec, &k, &[&xs, gamma, beta], &[&ys], &[u(c / lanes), f(eps)], band.len())?;
    }
    Ok(())
}

/// Bands of whole rows of `x` and `out` that fit one binding (one band when both fit).
fn row_bands(
    rec: &Recorder,
    what: &str,
    x: &Tensor,
    out: &Tensor,
    rows: usize,
    c: usize,
) -> Result<impl Iterator<Item = std::ops::Range<usize>>> {
    let per =
        if fit(rec.context(), &[x, out]) { rows } else { rows_per_band(rec.context(), what, &[c * elem(x)], 0, 1)? };
    Ok(bands(rows, per))
}

/// Softmax of scale·x over the last dimension.
pub fn softmax(rec: &mut Recorder, x: &Tensor, out: &Tensor, scale: f32) -> Result<()> {
    let dtype = same_dtype(rec.context(), "softmax", &[x, out])?;
    let (rows, c) = rows_of(x, "softmax")?;
    ensure(out.shape() == x.shape(), || "softmax: output shape mismatch".into())?;
    let k = kernel(rec.context(), "softmax", dtype, &[], 2)?;
    for band in row_bands(rec, "softmax", x, out, rows, c)? {
        let (xs, ys) = (row_view(x, c, band.clone())?, row_view(out, c, band.clone())?);
        dispatch_flat(rec, &k, &[&xs], &[&ys], &[u(c), f(scale)], band.len())?;
    }
    Ok(())
}
