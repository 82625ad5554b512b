//! Attention over heads wider than the flash kernels' registers hold (the VAE's single head of
//! 512 channels, in f32 as SDXL's VAE runs): softmax(scale·Q·Kᵀ)·V as two matrix products and a
//! row softmax, in chunks of query rows whose scores fit a bounded scratch. The products run on
//! the device's GEMM family, several times the rate of a flash kernel that holds a 512-wide
//! head (measured in BENCHMARKS.md), and the scores stay f32.

use super::attention::AttentionLayout;
use super::bands::{bands, row_view, span_view};
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

/// Query rows a chunk takes, or None where this path does not apply: f16 (whose scores would
/// round to f16), heads of up to [`WIDEST_FLASH_HEAD`], causal masks, key counts or row strides
/// off the vec4 grid, heads that do not start on the binding alignment, K or V past one binding.
pub(super) fn rows_per_chunk(rec: &Recorder, dtype: Dtype, l: &AttentionLayout) -> Option<usize> {
    let ctx = rec.context();
    if dtype != Dtype::F32 || l.head_dim <= WIDEST_FLASH_HEAD || l.causal || !l.kv_tokens.is_multiple_of(4) {
        return None;
    }
    let step = ctx.info().binding_alignment() as usize / 4;
    let starts = [l.head_dim, l.q_offset, l.k_offset, l.v_offset, l.q_batch, l.k_batch, l.v_batch, l.o_batch];
    let limit = ctx.binding_limit() as usize;
    let fits = |ld: usize| 4 * span(l.kv_tokens, ld, l.head_dim) <= limit;
    let vec4 = [l.q_ld, l.k_ld, l.v_ld, l.o_ld].iter().all(|ld| ld.is_multiple_of(4));
    if !vec4 || starts.iter().any(|s| !s.is_multiple_of(step)) || !fits(l.k_ld) || !fits(l.v_ld) {
        return None;
    }
    // A chunk's scores, and its rows of Q and of the output, each fit one binding; chunks start
    // on the alignment in Q and the output whatever their row strides.
    let rows = (SCORE_BYTES.min(limit) / (4 * l.kv_tokens)).min(limit / (4 * l.q_ld.max(l.o_ld)));
    let rows = rows - rows % step.max(64);
    (rows > 0).then(|| rows.min(l.q_tokens))
}

/// Elements spanned by `rows` rows of stride `ld` whose last row is `width` wide.
fn span(rows: usize, ld: usize, width: usize) -> usize {
    (rows - 1) * ld + width
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
    // Elements `start..` of `t` for `count` rows of stride `ld`, as a view starting there.
    let view = |t: &Tensor, start: usize, count: usize, ld: usize| -> Result<Tensor> {
        let (view, before) = span_view(t, start..start + span(count, ld, d))?;
        ensure(before == 0, || format!("attention: head at element {start} is off the binding alignment"))?;
        Ok(view)
    };
    for b in 0..l.batch {
        for h in 0..l.heads {
            let head = h * d;
            let keys = view(k, l.k_offset + b * l.k_batch + head, nk, l.k_ld)?;
            let values = view(v, l.v_offset + b * l.v_batch + head, nk, l.v_ld)?;
            for chunk in bands(l.q_tokens, rows) {
                let n = chunk.len();
                let queries = view(q, l.q_offset + b * l.q_batch + chunk.start * l.q_ld + head, n, l.q_ld)?;
                let outputs = view(out, b * l.o_batch + chunk.start * l.o_ld + head, n, l.o_ld)?;
                let s = row_view(&scores, nk, 0..n)?;
                let qk = Matmul { lda: l.q_ld, ldb: l.k_ld, alpha: scale, ..Matmul::dense(n, nk, d, true) };
                matmul(rec, &queries, &keys, None, &s, &qk)?;
                softmax(rec, &s, &s, 1.0)?;
                let pv = Matmul { ldb: l.v_ld, ldc: l.o_ld, ..Matmul::dense(n, d, nk, false) };
                matmul(rec, &s, &values, None, &outputs, &pv)?;
            }
        }
    }
    Ok(())
}
