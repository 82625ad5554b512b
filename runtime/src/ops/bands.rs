//! Work on tensors larger than one binding allows (lavapipe: 128 MiB; a VAE decode at 1024² in
//! f32 makes 512 MiB–1 GiB activations): the tensor lives in one buffer, and an op records one
//! dispatch per band of rows, each binding only its band's views. The result is exactly the
//! whole-tensor result; there are no tiles to blend and no seams.

use crate::context::Context;
use crate::error::{ensure, Result};
use crate::tensor::{dtype_size, Tensor};
use std::ops::Range;

/// Whether every tensor fits in one binding.
pub(super) fn fit(ctx: &Context, tensors: &[&Tensor]) -> bool {
    tensors.iter().all(|t| t.bytes() <= ctx.choices().binding_limit)
}

/// Rows `rows` of a tensor seen as [rows_total, row_len] (row_len = elements per row), as a view
/// of that shape.
pub(super) fn row_view(t: &Tensor, row_len: usize, rows: Range<usize>) -> Result<Tensor> {
    t.reshape(&[t.numel() / row_len, row_len])?.narrow(rows.start, rows.len())
}

/// Rows `rows` of image `b` of an NHWC tensor, as a [1, rows, W, C] view.
pub(super) fn image_rows(t: &Tensor, b: usize, rows: Range<usize>) -> Result<Tensor> {
    let [h, w, c] = [t.shape()[1], t.shape()[2], t.shape()[3]];
    let n = rows.len();
    row_view(t, w * c, b * h + rows.start..b * h + rows.end)?.reshape(&[1, n, w, c])
}

/// The most rows one binding holds of tensors whose rows take `row_bytes` bytes each (plus
/// `halo` further rows), such that every band starts on the device's binding alignment in each
/// tensor, and as a multiple of `multiple` when possible.
pub(super) fn rows_per_band(
    ctx: &Context,
    what: &str,
    row_bytes: &[usize],
    halo: usize,
    multiple: usize,
) -> Result<usize> {
    let widest = row_bytes.iter().copied().max().unwrap_or(1).max(1);
    let fit = (ctx.choices().binding_limit as usize / widest).saturating_sub(halo);
    ensure(fit > 0, || {
        format!("{what}: one row of {widest} bytes does not fit the {} byte binding limit", ctx.choices().binding_limit)
    })?;
    let align = ctx.info().binding_alignment() as usize;
    let aligned = row_bytes.iter().fold(1, |step, &b| lcm(step, align / gcd(align, b.max(1))));
    ensure(fit >= aligned, || {
        format!(
            "{what}: {fit} rows fit the binding limit, fewer than the {aligned} that keep bands on the device's \
            {align}-byte alignment"
        )
    })?;
    let step = if fit >= lcm(aligned, multiple) { lcm(aligned, multiple) } else { aligned };
    Ok(fit - fit % step)
}

fn gcd(a: usize, b: usize) -> usize {
    if b == 0 {
        a
    } else {
        gcd(b, a % b)
    }
}

fn lcm(a: usize, b: usize) -> usize {
    a / gcd(a, b) * b
}

/// Elements `range` of `t` (flat) as a view that starts at the binding-aligned element at or
/// before `range.start`, and how many elements before it that is (the view's offset to pass).
pub(super) fn span_view(t: &Tensor, range: Range<usize>) -> Result<(Tensor, usize)> {
    let step = t.context().info().binding_alignment() as usize / elem(t);
    let start = range.start - range.start % step.max(1);
    Ok((row_view(t, 1, start..range.end)?, range.start - start))
}

/// Consecutive ranges of at most `per` covering 0..n.
pub(super) fn bands(n: usize, per: usize) -> impl Iterator<Item = Range<usize>> {
    (0..n).step_by(per.max(1)).map(move |s| s..(s + per).min(n))
}

/// Bytes of one element of a tensor.
pub(super) fn elem(t: &Tensor) -> usize {
    dtype_size(t.dtype())
}
