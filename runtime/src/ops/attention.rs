//! Fused multi-head attention (flash-style: no Nq×Nk scores in memory).

use super::{dispatch_flat, element_groups, f, kernel, same_dtype, u};
use crate::error::{ensure, Error, Result};
use crate::recorder::Recorder;
use crate::tensor::Tensor;

/// Where attention's operands live. Element (b, token, head, d) of each is at
/// `offset + b·batch + token·ld + head·head_dim + d`, so Q, K and V can be column slices of one
/// fused projection (row stride 3·heads·head_dim, offsets 0, C and 2C).
#[derive(Clone, Debug)]
pub struct AttentionLayout {
    pub batch: usize,
    pub heads: usize,
    pub head_dim: usize,
    pub q_tokens: usize,
    pub kv_tokens: usize,
    pub q_ld: usize,
    pub k_ld: usize,
    pub v_ld: usize,
    pub o_ld: usize,
    pub q_batch: usize,
    pub k_batch: usize,
    pub v_batch: usize,
    pub o_batch: usize,
    pub q_offset: usize,
    pub k_offset: usize,
    pub v_offset: usize,
    /// Query i attends to keys 0..=i only (CLIP's text transformer).
    pub causal: bool,
}

impl AttentionLayout {
    /// Dense [B, tokens, heads·head_dim] tensors for Q, K, V and the output.
    pub fn dense(batch: usize, heads: usize, head_dim: usize, q_tokens: usize, kv_tokens: usize) -> AttentionLayout {
        let w = heads * head_dim;
        AttentionLayout {
            batch,
            heads,
            head_dim,
            q_tokens,
            kv_tokens,
            q_ld: w,
            k_ld: w,
            v_ld: w,
            o_ld: w,
            q_batch: q_tokens * w,
            k_batch: kv_tokens * w,
            v_batch: kv_tokens * w,
            o_batch: q_tokens * w,
            q_offset: 0,
            k_offset: 0,
            v_offset: 0,
            causal: false,
        }
    }
}

/// Subgroup widths attention has variants for.
const WIDTHS: [u32; 4] = [8, 16, 32, 64];

/// out = softmax(scale · Q·Kᵀ)·V for every batch and head.
pub fn attention(rec: &mut Recorder, q: &Tensor, k: &Tensor, v: &Tensor, out: &Tensor, l: &AttentionLayout, scale: f32) -> Result<()> {
    let dtype = same_dtype(rec.context(), "attention", &[q, k, v, out])?;
    ensure(l.batch > 0 && l.heads > 0 && l.q_tokens > 0 && l.kv_tokens > 0, || format!("attention: empty layout {l:?}"))?;
    ensure(!l.causal || l.q_tokens == l.kv_tokens, || format!("attention: a causal mask needs as many queries as keys, got {l:?}"))?;
    let need = |ld: usize, bs: usize, tokens: usize| (l.batch - 1) * bs + (tokens - 1) * ld + l.heads * l.head_dim;
    let need_at = |off: usize, ld: usize, bs: usize, tokens: usize| off + need(ld, bs, tokens);
    ensure(q.numel() >= need_at(l.q_offset, l.q_ld, l.q_batch, l.q_tokens), || format!("attention: Q {:?} too small", q.shape()))?;
    ensure(k.numel() >= need_at(l.k_offset, l.k_ld, l.k_batch, l.kv_tokens), || format!("attention: K {:?} too small", k.shape()))?;
    ensure(v.numel() >= need_at(l.v_offset, l.v_ld, l.v_batch, l.kv_tokens), || format!("attention: V {:?} too small", v.shape()))?;
    ensure(out.numel() >= need(l.o_ld, l.o_batch, l.q_tokens), || format!("attention: output {:?} too small", out.shape()))?;
    let strides = [l.head_dim, l.q_ld, l.k_ld, l.v_ld, l.o_ld, l.q_batch, l.k_batch, l.v_batch, l.o_batch, l.q_offset, l.k_offset, l.v_offset];
    if strides.iter().any(|s| s % 4 != 0) {
        return padded_attention(rec, [q, k, v], out, l, scale);
    }
    let ctx = rec.context().clone();
    let native = ctx.info().subgroup_size;
    let mut widths: Vec<u32> = WIDTHS.iter().copied().filter(|&w| ctx.subgroup_ok(w)).collect();
    widths.sort_by_key(|&w| (w != native, w));
    let slots = (l.head_dim / 4) as u32;
    let variant = widths.iter().find_map(|&sg| {
        vkdiff_kernels::variants("attention", dtype)
            .filter(|v| v.param("SG") == Some(sg) && v.param("DV").unwrap() * sg >= slots)
            .min_by_key(|v| v.param("DV"))
    });
    let variant = variant.ok_or_else(|| Error::Unsupported {
        device: ctx.info().name.clone(),
        reason: format!("no attention variant for head dim {} with subgroup widths {widths:?}", l.head_dim),
    })?;
    let tm = variant.param("TM").unwrap() as usize;
    let sg = variant.param("SG").unwrap();
    let kern = kernel(&ctx, "attention", dtype, &[("SG", sg), ("DV", variant.param("DV").unwrap()), ("TM", tm as u32)], 4)?;
    let push = [
        u(l.q_tokens), u(l.kv_tokens), u(l.head_dim), u(l.q_ld), u(l.k_ld), u(l.v_ld), u(l.o_ld),
        u(l.q_batch), u(l.k_batch), u(l.v_batch), u(l.o_batch), f(scale), u(l.q_offset), u(l.k_offset), u(l.v_offset),
        l.causal as u32,
    ];
    rec.dispatch(&kern, &[q, k, v], &[out], &push, [u(l.q_tokens.div_ceil(tm)), u(l.heads), u(l.batch)])
}

/// Attention on operands whose head size or strides are not multiples of 4 (the kernel reads
/// vec4s): each copied into a dense layout with its heads padded by zeros to a multiple of 4,
/// which add nothing to Q·Kᵀ and only make output columns that are then left behind.
fn padded_attention(rec: &mut Recorder, [q, k, v]: [&Tensor; 3], out: &Tensor, l: &AttentionLayout, scale: f32) -> Result<()> {
    let ctx = rec.context().clone();
    let padded = l.head_dim.next_multiple_of(4);
    let dense = AttentionLayout { causal: l.causal, ..AttentionLayout::dense(l.batch, l.heads, padded, l.q_tokens, l.kv_tokens) };
    let span = |offset, ld, batch, head_dim| HeadSpan { offset, ld, batch, head_dim };
    let dense_span = |tokens: usize| span(0, l.heads * padded, tokens * l.heads * padded, padded);
    let pad = |rec: &mut Recorder, t: &Tensor, from: HeadSpan, tokens: usize| -> Result<Tensor> {
        let to = ctx.zeros(&[l.batch, tokens, l.heads * padded], t.dtype())?;
        copy_heads(rec, t, &to, from, dense_span(tokens), l.batch, tokens, l.heads)?;
        Ok(to)
    };
    let q_dense = pad(rec, q, span(l.q_offset, l.q_ld, l.q_batch, l.head_dim), l.q_tokens)?;
    let k_dense = pad(rec, k, span(l.k_offset, l.k_ld, l.k_batch, l.head_dim), l.kv_tokens)?;
    let v_dense = pad(rec, v, span(l.v_offset, l.v_ld, l.v_batch, l.head_dim), l.kv_tokens)?;
    let o_dense = ctx.zeros(&[l.batch, l.q_tokens, l.heads * padded], out.dtype())?;
    attention(rec, &q_dense, &k_dense, &v_dense, &o_dense, &dense, scale)?;
    copy_heads(rec, &o_dense, out, dense_span(l.q_tokens), span(0, l.o_ld, l.o_batch, l.head_dim), l.batch, l.q_tokens, l.heads)
}

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
/// head, and zeros where `dst`'s heads are wider.
#[allow(clippy::too_many_arguments)]
pub fn copy_heads(rec: &mut Recorder, src: &Tensor, dst: &Tensor, from: HeadSpan, to: HeadSpan, batch: usize, tokens: usize, heads: usize) -> Result<()> {
    let dtype = same_dtype(rec.context(), "copy_heads", &[src, dst])?;
    let extent = |s: HeadSpan| s.offset + (batch - 1) * s.batch + (tokens - 1) * s.ld + heads * s.head_dim;
    ensure(batch > 0 && tokens > 0 && heads > 0 && from.head_dim > 0 && to.head_dim > 0, || "copy_heads: empty layout".into())?;
    ensure(src.numel() >= extent(from) && dst.numel() >= extent(to), || {
        format!("copy_heads: {from:?} of {:?} into {to:?} of {:?} for {batch}×{tokens}×{heads} heads", src.shape(), dst.shape())
    })?;
    let n = batch * tokens * heads * to.head_dim;
    let k = kernel(rec.context(), "copy_heads", dtype, &[], 2)?;
    let push = [n, tokens, heads, from.head_dim, to.head_dim, from.ld, to.ld, from.batch, to.batch, from.offset, to.offset].map(u);
    dispatch_flat(rec, &k, &[src], &[dst], &push, element_groups(n))
}
