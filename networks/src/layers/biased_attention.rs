//! Self-attention whose q/k/v projections carry biases (CLIP's text and vision transformers,
//! the VAE's mid block), with the three fused into one GEMM.

use crate::error::Result;
use crate::layers::nn::{Graph, Linear};
use crate::weights::Weights;
use vkdiff_runtime::ops::{self, AttentionLayout};
use vkdiff_runtime::Tensor;

pub struct BiasedSelfAttention {
    qkv: Linear,
    out: Linear,
    heads: usize,
}

impl BiasedSelfAttention {
    /// `names` are the q, k, v and output projections' names under `w`.
    pub fn load(w: &Weights, [q, k, v, out]: [&str; 4], channels: usize, heads: usize) -> Result<BiasedSelfAttention> {
        let weight =
            w.stacked(&[&format!("{q}.weight"), &format!("{k}.weight"), &format!("{v}.weight")], channels, channels)?;
        let bias = w
            .stacked(&[&format!("{q}.bias"), &format!("{k}.bias"), &format!("{v}.bias")], channels, 1)?
            .reshape(&[3 * channels])?;
        Ok(BiasedSelfAttention {
            qkv: Linear { weight, bias: Some(bias) },
            out: Linear::load(w, out, channels, channels, true)?,
            heads,
        })
    }

    /// residual[B, N, C] += out_proj(attention(x)), x [B, N, C].
    pub fn forward_residual(&self, g: &mut Graph, x: &Tensor, residual: &Tensor, causal: bool) -> Result<()> {
        let [b, n, c] = [x.shape()[0], x.shape()[1], x.shape()[2]];
        let qkv = self.qkv.forward(g, x)?;
        let head_dim = c / self.heads;
        let mut l = AttentionLayout::dense(b, self.heads, head_dim, n, n);
        (l.q_ld, l.k_ld, l.v_ld) = (3 * c, 3 * c, 3 * c);
        (l.q_batch, l.k_batch, l.v_batch) = (3 * n * c, 3 * n * c, 3 * n * c);
        (l.k_offset, l.v_offset) = (c, 2 * c);
        l.causal = causal;
        let attn = g.alloc(&[b, n, c])?;
        ops::attention(&mut g.rec, &qkv, &qkv, &qkv, &attn, &l, 1.0 / (head_dim as f32).sqrt())?;
        self.out.forward_into(g, &attn, residual, true, 1.0)
    }
}
