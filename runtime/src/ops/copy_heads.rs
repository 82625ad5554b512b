//! Copies of attention heads between layouts (with widening or rounding between f16 and f32):
//! how attention, its products and the padded convolution reach operands the kernels cannot
//! read in place.

use super::bands::{bands, elem, fit, rows_per_band, span_view};
use super::{dispatch_flat, element_groups, kernel, same_dtype, u};
use crate::error::{ensure, Result};
use crate::recorder::Recorder;
use crate::tensor::{Dtype, Tensor};

/// Where the heads of one operand lie: element (b, token, head, d) at
/// `offset + b·batch + token·ld + head·head_dim + d`.
#[derive(Clone, Copy, Debug)]
pub struct HeadSpan {
    pub offset: usize,
    pub ld: usize,
    pub batch: usize,
    pub head_dim: usize,
}

/// Copies every head of `src` into `dst`'s layout: the first min(head sizes) values of each
/// head, and zeros where `dst`'s heads are wider. f16 heads into an f32 tensor are widened,
/// f32 ones into an f16 tensor rounded.
#[allow(clippy::too_many_arguments)]
pub fn copy_heads(
    rec: &mut Recorder,
    src: &Tensor,
    dst: &Tensor,
    from: HeadSpan,
    to: HeadSpan,
    batch: usize,
    tokens: usize,
    heads: usize,
) -> Result<()> {
    let (name, dtype) = match (src.dtype(), dst.dtype()) {
        (Dtype::F16, Dtype::F32) => ("copy_heads_to_f32", Dtype::F16),
        (Dtype::F32, Dtype::F16) => ("copy_heads_from_f32", Dtype::F16),
        _ => ("copy_heads", src.dtype()),
    };
    same_dtype(rec.context(), "copy_heads", &[src])?;
    same_dtype(rec.context(), "copy_heads", &[dst])?;
    let extent = |s: HeadSpan| s.offset + (batch - 1) * s.batch + (tokens - 1) * s.ld + heads * s.head_dim;
    ensure(batch > 0 && tokens > 0 && heads > 0 && from.head_dim > 0 && to.head_dim > 0, || {
        "copy_heads: empty layout".into()
    })?;
    ensure(src.numel() >= extent(from) && dst.numel() >= extent(to), || {
        format!(
            "copy_heads: {from:?} of {:?} into {to:?} of {:?} for {batch}×{tokens}×{heads} heads",
            src.shape(),
            dst.shape()
        )
    })?;
    let k = kernel(rec.context(), name, dtype, &[], 2)?;
    let record =
        |rec: &mut Recorder, src: &Tensor, dst: &Tensor, from: HeadSpan, to: HeadSpan, batch: usize, tokens: usize| {
            let n = batch * tokens * heads * to.head_dim;
            let push = [
                n,
                tokens,
                heads,
                from.head_dim,
                to.head_dim,
                from.ld,
                to.ld,
                from.batch,
                to.batch,
                from.offset,
                to.offset,
            ]
            .map(u);
            dispatch_flat(rec, &k, &[src], &[dst], &push, element_groups(n))
        };
    if fit(rec.context(), &[src, dst]) {
        return record(rec, src, dst, from, to, batch, tokens);
    }
    // Past the binding limit: bands of tokens of one batch at a time, each on views of the rows
    // it reads and writes.
    let row_bytes = [from.ld.max(from.head_dim) * elem(src), to.ld.max(to.head_dim) * elem(dst)];
    // A band's view may start up to one alignment before its first row and end a row of heads after its last.
    let align = rec.context().info().binding_alignment() as usize;
    let halo = 1 + align.div_ceil(row_bytes[0].min(row_bytes[1]));
    let per = rows_per_band(rec.context(), "copy_heads", &row_bytes, halo, 1)?;
    let rows = |s: HeadSpan, b: usize, t: &std::ops::Range<usize>| {
        let start = s.offset + b * s.batch + t.start * s.ld;
        start..start + (t.len() - 1) * s.ld + heads * s.head_dim
    };
    for b in 0..batch {
        for band in bands(tokens, per) {
            let (sv, src_offset) = span_view(src, rows(from, b, &band))?;
            let (dv, dst_offset) = span_view(dst, rows(to, b, &band))?;
            record(
                rec,
                &sv,
                &dv,
                HeadSpan { offset: src_offset, batch: 0, ..from },
                HeadSpan { offset: dst_offset, batch: 0, ..to },
                1,
                band.len(),
            )?;
        }
    }
    Ok(())
}
