//! Element-wise and data-movement operations.

use super::bands::{bands, elem, fit, image_rows, row_view, rows_per_band};
use super::{dispatch_flat, element_groups, f, kernel, same_dtype, u, unit_kernel};
use crate::error::{ensure, Result};
use crate::recorder::Recorder;
use crate::tensor::{Dtype, Tensor};
use std::ops::Range;

/// Unary functions, numbered as in `kernels/wgsl/unary.wgsl`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UnaryOp {
    /// alpha · x
    Scale = 0,
    Silu = 1,
    /// GELU with the exact erf form (PyTorch's default).
    Gelu = 2,
    /// GELU with the tanh approximation (`approximate="tanh"`).
    GeluTanh = 3,
    /// x · sigmoid(1.702 x), as in OpenAI CLIP.
    QuickGelu = 4,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BinaryOp {
    Add = 0,
    Mul = 1,
}

/// out = op(x), element-wise; `alpha` is used by `Scale`. `out` may be `x`. Past the binding
/// limit, in consecutive runs of elements.
pub fn unary(rec: &mut Recorder, op: UnaryOp, x: &Tensor, out: &Tensor, alpha: f32) -> Result<()> {
    let dtype = same_dtype(rec.context(), "unary", &[x, out])?;
    ensure(x.numel() == out.numel(), || format!("{op:?}: {:?} into {:?}", x.shape(), out.shape()))?;
    let n = x.numel();
    let per = if fit(rec.context(), &[x, out]) { n } else { rows_per_band(rec.context(), "unary", &[elem(x)], 0, 64)? };
    let (k, unit) =
        unit_kernel(rec.context(), &[("unary_v4", 4), ("unary", 1)], dtype, &[("OP", op as u32)], 2, &[n, per])?;
    for run in bands(n, per) {
        let (xs, ys) = (row_view(x, 1, run.clone())?, row_view(out, 1, run.clone())?);
        let units = run.len() / unit;
        dispatch_flat(rec, &k, &[&xs], &[&ys], &[u(units), f(alpha)], element_groups(units))?;
    }
    Ok(())
}

/// out = a op b, where b's flat index is `(i / b_outer)·b_inner + i % b_inner` (see binary.wgsl).
/// Past the binding limit, in runs of elements, each binding the part of b it reads.
pub fn binary(
    rec: &mut Recorder,
    op: BinaryOp,
    a: &Tensor,
    b: &Tensor,
    out: &Tensor,
    b_inner: usize,
    b_outer: usize,
) -> Result<()> {
    let dtype = same_dtype(rec.context(), "binary", &[a, b, out])?;
    let n = a.numel();
    ensure(out.numel() == n && b_inner > 0 && b_outer > 0, || {
        format!("{op:?}: {:?} into {:?}", a.shape(), out.shape())
    })?;
    ensure((n - 1) / b_outer * b_inner + b_inner.min(n) <= b.numel(), || {
        format!("{op:?}: {:?} cannot broadcast over {:?}", b.shape(), a.shape())
    })?;
    let ctx = rec.context().clone();
    let (names, want) = (&[("binary_v4", 4), ("binary", 1)], [("OP", op as u32)]);
    if fit(&ctx, &[a, b, out]) {
        let (k, unit) = unit_kernel(&ctx, names, dtype, &want, 3, &[n, b_inner, b_outer])?;
        let push = [n, b_inner, b_outer].map(|c| u(c / unit));
        return dispatch_flat(rec, &k, &[a, b], &[out], &[push[0], push[1], push[2], 0, 0], element_groups(n / unit));
    }
    // b's view starts at an aligned element at or before the run's first index, so it may take
    // up to `slack` elements more than the run. With vec4 units every run starts on a multiple
    // of 4, and so does b's view: slack is a power of two, and what b reads starts on a unit.
    let slack = (ctx.info().binding_alignment() as usize).div_ceil(elem(b));
    let per = rows_per_band(&ctx, "binary", &[elem(a)], slack, 64)?;
    let (k, unit) = unit_kernel(&ctx, names, dtype, &want, 3, &[n, b_inner, b_outer, per])?;
    for run in bands(n, per) {
        let reads = broadcast_span(run.clone(), b_inner, b_outer);
        let first = reads.start - reads.start % slack;
        let (xs, ys, bs) =
            (row_view(a, 1, run.clone())?, row_view(out, 1, run.clone())?, row_view(b, 1, first..reads.end)?);
        let push = [run.len(), b_inner, b_outer, run.start, first].map(|c| u(c / unit));
        dispatch_flat(rec, &k, &[&xs, &bs], &[&ys], &push, element_groups(run.len() / unit))?;
    }
    Ok(())
}

/// The indices `(i / outer)·inner + i % inner` of b that the elements i in `run` read: within
/// one block of `outer` elements they are contiguous unless i % inner wraps around.
fn broadcast_span(run: Range<usize>, inner: usize, outer: usize) -> Range<usize> {
    let wraps = |from: usize, to: usize| to - from >= inner || from % inner > to % inner;
    let (s, e) = (run.start, run.end - 1);
    let first_block_end = ((s / outer + 1) * outer - 1).min(e);
    let lo = s / outer * inner + if wraps(s, first_block_end) { 0 } else { s % inner };
    let last_block_start = (e / outer * outer).max(s);
    let hi = e / outer * inner + if wraps(last_block_start, e) { inner - 1 } else { e % inner };
    lo..hi + 1
}

/// `binary`'s (b_inner, b_outer) for NumPy-style broadcasting of b over a, in the shapes
/// networks use: b's shape equals a's trailing dimensions, or is [a.0, 1, ..., 1, C] (a
/// per-batch, per-channel vector).
fn broadcast(a: &Tensor, b: &Tensor) -> Result<(usize, usize)> {
    let (sa, sb) = (a.shape(), b.shape());
    if sb.len() <= sa.len() && sa[sa.len() - sb.len()..] == *sb {
        return Ok((b.numel(), a.numel()));
    }
    let c = *sa.last().unwrap_or(&1);
    if sb.len() == sa.len() && sb[0] == sa[0] && sb.last() == Some(&c) && b.numel() == sa[0] * c {
        return Ok((c, a.numel() / sa[0]));
    }
    Err(crate::Error::Shape(format!("cannot broadcast {sb:?} over {sa:?}")))
}

/// out = a + b with NumPy-style broadcasting of b (see [`broadcast`]).
pub fn add(rec: &mut Recorder, a: &Tensor, b: &Tensor, out: &Tensor) -> Result<()> {
    let (inner, outer) = broadcast(a, b)?;
    binary(rec, BinaryOp::Add, a, b, out, inner, outer)
}

/// out = a · b with NumPy-style broadcasting of b (see [`broadcast`]).
pub fn mul(rec: &mut Recorder, a: &Tensor, b: &Tensor, out: &Tensor) -> Result<()> {
    let (inner, outer) = broadcast(a, b)?;
    binary(rec, BinaryOp::Mul, a, b, out, inner, outer)
}

/// GEGLU: x[.., 2F] → out[.., F] = value · GELU(gate), value first; in bands of rows past the
/// binding limit.
pub fn geglu(rec: &mut Recorder, x: &Tensor, out: &Tensor) -> Result<()> {
    let dtype = same_dtype(rec.context(), "geglu", &[x, out])?;
    let two_f = *x.shape().last().unwrap_or(&0);
    ensure(two_f.is_multiple_of(2) && two_f > 0 && out.numel() * 2 == x.numel(), || {
        format!("geglu: {:?} into {:?}", x.shape(), out.shape())
    })?;
    // Four values per invocation where F allows (every SDXL and CLIP width).
    let (k, lanes) = unit_kernel(rec.context(), &[("geglu_v4", 4), ("geglu", 1)], dtype, &[], 2, &[two_f / 2])?;
    let rows = x.numel() / two_f;
    let per = if fit(rec.context(), &[x, out]) {
        rows
    } else {
        rows_per_band(rec.context(), "geglu", &[two_f * elem(x), two_f / 2 * elem(x)], 0, 64)?
    };
    for band in bands(rows, per) {
        let (xs, ys) = (row_view(x, two_f, band.clone())?, row_view(out, two_f / 2, band)?);
        let n = ys.numel() / lanes;
        dispatch_flat(rec, &k, &[&xs], &[&ys], &[u(n), u(two_f / 2 / lanes)], element_groups(n))?;
    }
    Ok(())
}

/// Nearest 2× upsampling of x[B, H, W, C] into out[B, 2H, 2W, C]; in bands of rows past the
/// binding limit.
pub fn upsample_nearest2x(rec: &mut Recorder, x: &Tensor, out: &Tensor) -> Result<()> {
    let dtype = same_dtype(rec.context(), "upsample", &[x, out])?;
    let s = x.shape().to_vec();
    ensure(s.len() == 4 && out.shape() == [s[0], 2 * s[1], 2 * s[2], s[3]], || {
        format!("upsample: {:?} into {:?}", s, out.shape())
    })?;
    let names = &[("upsample_nearest2x_v4", 4), ("upsample_nearest2x", 1)];
    let (k, unit) = unit_kernel(rec.context(), names, dtype, &[], 2, &[s[3]])?;
    if fit(rec.context(), &[x, out]) {
        let n = out.numel() / unit;
        return dispatch_flat(rec, &k, &[x], &[out], &[u(n), u(s[1]), u(s[2]), u(s[3] / unit)], element_groups(n));
    }
    let per = rows_per_band(
        rec.context(),
        "upsample",
        &[2 * out.shape()[2] * s[3] * elem(out), s[2] * s[3] * elem(x)],
        0,
        1,
    )?;
    for image in 0..s[0] {
        for rows in bands(s[1], per) {
            let (xs, ys) = (image_rows(x, image, rows.clone())?, image_rows(out, image, 2 * rows.start..2 * rows.end)?);
            let n = ys.numel() / unit;
            let push = [u(n), u(rows.len()), u(s[2]), u(s[3] / unit)];
            dispatch_flat(rec, &k, &[&xs], &[&ys], &push, element_groups(n))?;
        }
    }
    Ok(())
}

/// out[.., C1 + C2] = [a[.., C1], b[.., C2]] along the last (channel) dimension.
pub fn concat_channels(rec: &mut Recorder, a: &Tensor, b: &Tensor, out: &Tensor) -> Result<()> {
    let dtype = same_dtype(rec.context(), "concat", &[a, b, out])?;
    let (c1, c2) = (*a.shape().last().unwrap_or(&0), *b.shape().last().unwrap_or(&0));
    let lead = |t: &Tensor| t.shape()[..t.shape().len() - 1].to_vec();
    ensure(
        c1 > 0 && c2 > 0 && lead(a) == lead(b) && lead(out) == lead(a) && out.shape().last() == Some(&(c1 + c2)),
        || format!("concat: {:?} + {:?} into {:?}", a.shape(), b.shape(), out.shape()),
    )?;
    let names = &[("concat_channels_v4", 4), ("concat_channels", 1)];
    let (k, unit) = unit_kernel(rec.context(), names, dtype, &[], 3, &[c1, c2])?;
    let rows = a.numel() / c1;
    let per = if fit(rec.context(), &[a, b, out]) {
        rows
    } else {
        rows_per_band(rec.context(), "concat", &[c1 * elem(a), c2 * elem(a), (c1 + c2) * elem(a)], 0, 64)?
    };
    for band in bands(rows, per) {
        let (av, bv, ov) =
            (row_view(a, c1, band.clone())?, row_view(b, c2, band.clone())?, row_view(out, c1 + c2, band)?);
        let n = ov.numel() / unit;
        dispatch_flat(rec, &k, &[&av, &bv], &[&ov], &[u(n), u(c1 / unit), u(c2 / unit)], element_groups(n))?;
    }
    Ok(())
}

/// out[.., offset..offset + C] = x[.., C]: one branch of a channel concatenation written in place
/// (Inception's blocks join four branches). In bands of rows past the binding limit.
pub fn copy_into_channels(rec: &mut Recorder, x: &Tensor, out: &Tensor, offset: usize) -> Result<()> {
    let dtype = same_dtype(rec.context(), "copy_into_channels", &[x, out])?;
    let (c, c_out) = (*x.shape().last().unwrap_or(&0), *out.shape().last().unwrap_or(&0));
    let lead = |t: &Tensor| t.shape()[..t.shape().len().saturating_sub(1)].to_vec();
    ensure(c > 0 && lead(x) == lead(out) && offset + c <= c_out, || {
        format!("copy_into_channels: {:?} at channel {offset} of {:?}", x.shape(), out.shape())
    })?;
    let k = kernel(rec.context(), "copy_channels", dtype, &[], 2)?;
    let rows = x.numel() / c;
    let per = if fit(rec.context(), &[x, out]) {
        rows
    } else {
        rows_per_band(rec.context(), "copy_into_channels", &[c * elem(x), c_out * elem(x)], 0, 64)?
    };
    for band in bands(rows, per) {
        let (xv, ov) = (row_view(x, c, band.clone())?, row_view(out, c_out, band)?);
        dispatch_flat(
            rec,
            &k,
            &[&xv],
            &[&ov],
            &[u(xv.numel()), u(c), u(c_out), u(offset)],
            element_groups(xv.numel()),
        )?;
    }
    Ok(())
}

/// diffusers' `Timesteps` settings.
#[derive(Clone, Copy, Debug)]
pub struct TimestepEmbedding {
    pub dim: usize,
    pub flip_sin_to_cos: bool,
    pub downscale_freq_shift: f32,
    pub max_period: f32,
    pub scale: f32,
}

/// out[B, dim] = sinusoidal embedding of `timesteps` (f32, [B]).
pub fn timestep_embedding(rec: &mut Recorder, timesteps: &Tensor, out: &Tensor, e: &TimestepEmbedding) -> Result<()> {
    ensure(timesteps.dtype() == Dtype::F32, || "timestep_embedding: timesteps must be f32".into())?;
    let dtype = same_dtype(rec.context(), "timestep_embedding", &[out])?;
    let b = timesteps.numel();
    ensure(out.shape() == [b, e.dim], || {
        format!("timestep_embedding: output {:?}, expected [{b}, {}]", out.shape(), e.dim)
    })?;
    let k = kernel(rec.context(), "timestep_embedding", dtype, &[], 2)?;
    let push = [u(e.dim), u(b), e.flip_sin_to_cos as u32, f(e.downscale_freq_shift), f(e.max_period.ln()), f(e.scale)];
    rec.dispatch(&k, &[timesteps], &[out], &push, [u((b * e.dim).div_ceil(64)), 1, 1])
}
