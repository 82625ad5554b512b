//! Fused multi-head attention (flash-style: no Nq×Nk scores in memory).

use super::{f, kernel, same_dtype, u};
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
    let strides = [l.head_dim, l.q_ld, l.k_ld, l.v_ld, l.o_ld, l.q_batch, l.k_batch, l.v_batch, l.o_batch, l.q_offset, l.k_offset, l.v_offset];
    ensure(strides.iter().all(|s| s % 4 == 0), || format!("attention: head dim and strides must be multiples of 4, got {l:?}"))?;
    let need = |ld: usize, bs: usize, tokens: usize| (l.batch - 1) * bs + (tokens - 1) * ld + l.heads * l.head_dim;
    let need_at = |off: usize, ld: usize, bs: usize, tokens: usize| off + need(ld, bs, tokens);
    ensure(q.numel() >= need_at(l.q_offset, l.q_ld, l.q_batch, l.q_tokens), || format!("attention: Q {:?} too small", q.shape()))?;
    ensure(k.numel() >= need_at(l.k_offset, l.k_ld, l.k_batch, l.kv_tokens), || format!("attention: K {:?} too small", k.shape()))?;
    ensure(v.numel() >= need_at(l.v_offset, l.v_ld, l.v_batch, l.kv_tokens), || format!("attention: V {:?} too small", v.shape()))?;
    ensure(out.numel() >= need(l.o_ld, l.o_batch, l.q_tokens), || format!("attention: output {:?} too small", out.shape()))?;
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
