//! Attention over heads wider than the flash kernels' registers hold (the VAE's single head of
//! 512 channels): softmax(scale·Q·Kᵀ)·V as two matrix products and a row softmax, in chunks of
//! query rows whose scores fit a bounded scratch. The products run on the device's GEMM family,
//! several times the rate of a flash kernel that holds a 512-wide head (measured in
//! BENCHMARKS.md), and the scores stay f32: f16 heads (an fp16-fix VAE) are widened into f32
//! scratch first and the results rounded back, since f16 scores would lose the softmax's
//! precision.

use super::attention::AttentionLayout;
use super::bands::{bands, row_view, span_view};
use super::copy_heads::{copy_heads, HeadSpan};
use super::gemm::{matmul, Matmul};
use super::norm::softmax;
use crate::error::{ensure, Result};
use crate::recorder::Recorder;
use crate::tensor::{Dtype, Tensor};

/// Heads up to this many values stay on the flash kernels.
const WIDEST_FLASH_HEAD: usize = 128;

/// The most bytes of scores one chunk keeps (also held to the binding limit): at the VAE's
/// 1024² decode (16,384 tokens), 2,048 query rows a chunk, enough for a GPU's GEMM to fill it.
const SCORE_BYTES: usize = 128 << 20;

/// Query rows a chunk takes, or None where this path does not apply: heads of up to
/// [`WIDEST_FLASH_HEAD`], causal masks, key counts or heads off the vec4 grid, a head's keys (in
/// f32) past one binding; for f32 operands, which the products read in place, also row strides
/// off the vec4 grid and heads that do not start on the binding alignment.
pub(super) fn rows_per_chunk(rec: &Recorder, dtype: Dtype, l: &AttentionLayout) -> Option<usize> {
    let ctx = rec.context();
    let d = l.head_dim;
    if d <= WIDEST_FLASH_HEAD || !d.is_multiple_of(4) || l.causal || !l.kv_tokens.is_multiple_of(4) {
        return None;
    }
    let step = ctx.info().binding_alignment() as usize / 4;
    let limit = ctx.choices().binding_limit as usize;
    let fits = |ld: usize| 4 * span(l.kv_tokens, ld, d) <= limit;
    // The row strides of Q and the output that a chunk's f32 rows have.
    let ld = if dtype == Dtype::F32 {
        let starts = [l.q_offset, l.k_offset, l.v_offset, l.q_batch, l.k_batch, l.v_batch, l.o_batch];
        let vec4 = [l.q_ld, l.k_ld, l.v_ld, l.o_ld].iter().all(|ld| ld.is_multiple_of(4));
        if !vec4 || starts.iter().any(|s| !s.is_multiple_of(step)) || !fits(l.k_ld) || !fits(l.v_ld) {
            return None;
        }
        l.q_ld.max(l.o_ld)
    } else if fits(d) {
        d
    } else {
        return None;
    };
    // A chunk's scores, and its rows of Q and of the output, each fit one binding; chunks start
    // on the alignment in Q and the output whatever their row strides.
    let rows = (SCORE_BYTES.min(limit) / (4 * l.kv_tokens)).min(limit / (4 * ld));
    let rows = rows - rows % step.max(64);
    (rows > 0).then(|| rows.min(l.q_tokens))
}

/// Elements spanned by `rows` rows of stride `ld` whose last row is `width` wide.
fn span(rows: usize, ld: usize, width: usize) -> usize {
    (rows - 1) * ld + width
}

/// f32 copies of f16 operands: one head's keys and values, one chunk's queries and outputs.
struct Widened {
    keys: Tensor,
    values: Tensor,
    queries: Tensor,
    outputs: Tensor,
}

/// Records attention as products, `rows` query rows at a time (from [`rows_per_chunk`]).
pub(super) fn attention_by_products(
    rec: &mut Recorder,
    [q, k, v]: [&Tensor; 3],
    out: &Tensor,
    l: &AttentionLayout,
    scale: f32,
    rows: usize,
) -> Result<()> {
    let ctx = rec.context().clone();
    let (d, nk) = (l.head_dim, l.kv_tokens);
    let scores = ctx.zeros(&[rows, nk], Dtype::F32)?;
    let widened = match q.dtype() {
        Dtype::F32 => None,
        Dtype::F16 => {
            let rows_of = |n: usize| ctx.zeros(&[n, d], Dtype::F32);
            Some(Widened { keys: rows_of(nk)?, values: rows_of(nk)?, queries: rows_of(rows)?, outputs: rows_of(rows)? })
        }
    };
    let widened = widened.as_ref();
    // Rows `start..` of stride `ld` as a product reads them: a view in place, or (f16) widened
    // into the first rows of `scratch`; with the stride it has there.
    let operand = |rec: &mut Recorder, t: &Tensor, start: usize, count: usize, ld: usize, scratch: Option<&Tensor>| {
        let Some(scratch) = scratch else {
            let (view, before) = span_view(t, start..start + span(count, ld, d))?;
            ensure(before == 0, || format!("attention: head at element {start} is off the binding alignment"))?;
            return Ok((view, ld));
        };
        let to = row_view(scratch, d, 0..count)?;
        copy_heads(rec, t, &to, head_span(start, ld, d), head_span(0, d, d), 1, count, 1)?;
        Ok((to, d))
    };
    for b in 0..l.batch {
        for h in 0..l.heads {
            let head = h * d;
            let (keys, k_ld) =
                operand(rec, k, l.k_offset + b * l.k_batch + head, nk, l.k_ld, widened.map(|w| &w.keys))?;
            let (values, v_ld) =
                operand(rec, v, l.v_offset + b * l.v_batch + head, nk, l.v_ld, widened.map(|w| &w.values))?;
            for chunk in bands(l.q_tokens, rows) {
                let n = chunk.len();
                let q_start = l.q_offset + b * l.q_batch + chunk.start * l.q_ld + head;
                let (queries, q_ld) = operand(rec, q, q_start, n, l.q_ld, widened.map(|w| &w.queries))?;
                let o_start = b * l.o_batch + chunk.start * l.o_ld + head;
                let (outputs, o_ld) = match widened {
                    Some(w) => (row_view(&w.outputs, d, 0..n)?, d),
                    None => operand(rec, out, o_start, n, l.o_ld, None)?,
                };
                let s = row_view(&scores, nk, 0..n)?;
                let qk = Matmul { lda: q_ld, ldb: k_ld, alpha: scale, ..Matmul::dense(n, nk, d, true) };
                matmul(rec, &queries, &keys, None, &s, &qk)?;
                softmax(rec, &s, &s, 1.0)?;
                let pv = Matmul { ldb: v_ld, ldc: o_ld, ..Matmul::dense(n, d, nk, false) };
                matmul(rec, &s, &values, None, &outputs, &pv)?;
                if widened.is_some() {
                    copy_heads(rec, &outputs, out, head_span(0, d, d), head_span(o_start, l.o_ld, d), 1, n, 1)?;
                }
            }
        }
    }
    Ok(())
}

/// One head of `d` values a row, rows of stride `ld` from element `offset`.
fn head_span(offset: usize, ld: usize, d: usize) -> HeadSpan {
    HeadSpan { offset, ld, batch: 0, head_dim: d }
}
