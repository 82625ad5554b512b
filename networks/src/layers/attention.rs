//! diffusers `Attention` as SDXL's transformer blocks use it: self-attention with one fused QKV
//! projection, cross-attention with a fused KV projection of the context, and IP-Adapter's
//! decoupled image-token attention added on the cross-attentions.

use crate::error::{Error, Result};
use crate::layers::nn::{Graph, Linear};
use crate::weights::Weights;
use vkdiff_runtime::ops::{self, AttentionLayout};
use vkdiff_runtime::Tensor;

/// One IP-Adapter's decoupled attention weights for one cross-attention layer.
pub struct IpLayer {
    /// [channels, cross_attention_dim], no bias.
    pub to_k_ip: Linear,
    pub to_v_ip: Linear,
}

/// Extra key/value tokens on every cross-attention k:
/// `out = softmax(QKᵀ)V + scales[k] · softmax(QK_ipᵀ)V_ip`, with K_ip, V_ip projected from
/// `tokens` by each layer's own weights (once per conditioning, like the prompt's keys and
/// values). `layers` and `scales` are in the order of
/// [`crate::UNet::cross_attentions`].
pub struct IpAdapterInput {
    /// [B, image tokens, cross_attention_dim].
    pub tokens: Tensor,
    pub scales: Vec<f32>,
    pub layers: Vec<IpLayer>,
}

enum Projections {
    /// to_q, to_k, to_v stacked into one [3C, C] weight.
    SelfAttention(Linear),
    /// to_q, and to_k, to_v stacked into one [2C, context] weight.
    Cross { q: Linear, kv: Linear },
}

pub struct Attention {
    heads: usize,
    head_dim: usize,
    proj: Projections,
    to_out: Linear,
    /// Position among the network's cross-attentions (IP-Adapter layer index).
    cross_index: Option<usize>,
}

impl Attention {
    pub fn load_self(w: &Weights, channels: usize, heads: usize) -> Result<Attention> {
        let qkv = w.stacked(&["to_q.weight", "to_k.weight", "to_v.weight"], channels, channels)?;
        let proj = Projections::SelfAttention(Linear { weight: qkv, bias: None });
        Self::with(w, channels, heads, proj, None)
    }

    pub fn load_cross(
        w: &Weights,
        channels: usize,
        context: usize,
        heads: usize,
        cross_index: usize,
    ) -> Result<Attention> {
        let q = Linear::load(w, "to_q", channels, channels, false)?;
        // Keys and values of the prompt are projected once per conditioning, so their weights
        // live in host memory.
        let kv = w.in_host_memory().stacked(&["to_k.weight", "to_v.weight"], channels, context)?;
        let kv = Linear { weight: kv, bias: None };
        Self::with(w, channels, heads, Projections::Cross { q, kv }, Some(cross_index))
    }

    fn with(
        w: &Weights,
        channels: usize,
        heads: usize,
        proj: Projections,
        cross_index: Option<usize>,
    ) -> Result<Attention> {
        let to_out = Linear::load(w, "to_out.0", channels, channels, true)?;
        Ok(Attention { heads, head_dim: channels / heads, proj, to_out, cross_index })
    }

    /// residual += to_out(attention(x[B, N, C], context[B, T, D] or x)).
    pub fn forward_residual(
        &self,
        g: &mut Graph,
        x: &Tensor,
        context: Option<&Tensor>,
        ip: &[IpAdapterInput],
        residual: &Tensor,
    ) -> Result<()> {
        let (b, n) = (x.shape()[0], x.shape()[1]);
        let c = self.heads * self.head_dim;
        let scale = 1.0 / (self.head_dim as f32).sqrt();
        let out = g.alloc(&[b, n, c])?;
        let mut l = AttentionLayout::dense(b, self.heads, self.head_dim, n, n);
        match (&self.proj, context) {
            (Projections::SelfAttention(qkv), _) => {
                let qkv = qkv.forward(g, x)?;
                (l.q_ld, l.k_ld, l.v_ld) = (3 * c, 3 * c, 3 * c);
                (l.q_batch, l.k_batch, l.v_batch) = (3 * c * n, 3 * c * n, 3 * c * n);
                (l.k_offset, l.v_offset) = (c, 2 * c);
                ops::attention(&mut g.rec, &qkv, &qkv, &qkv, &out, &l, scale)?;
            }
            (Projections::Cross { q, kv }, Some(context)) => {
                let tokens = context.shape()[1];
                let q = q.forward(g, x)?;
                let kv = g.project_conditioning(kv, context, 1.0)?;
                l.kv_tokens = tokens;
                (l.k_ld, l.v_ld) = (2 * c, 2 * c);
                (l.k_batch, l.v_batch) = (2 * c * tokens, 2 * c * tokens);
                l.v_offset = c;
                ops::attention(&mut g.rec, &q, &kv, &kv, &out, &l, scale)?;
                for adapter in ip {
                    self.add_image_attention(g, &q, adapter, &out, scale)?;
                }
            }
            (Projections::Cross { .. }, None) => {
                return Err(Error::Config("cross-attention needs encoder hidden states".into()))
            }
        }
        self.to_out.forward_into(g, &out, residual, true, 1.0)
    }

    /// out += scale · softmax(Q·K_ipᵀ)·V_ip, the scale folded into V_ip's projection; nothing
    /// where the layer's scale is 0 (a style-only adapter leaves most layers out).
    fn add_image_attention(
        &self,
        g: &mut Graph,
        q: &Tensor,
        adapter: &IpAdapterInput,
        out: &Tensor,
        softmax_scale: f32,
    ) -> Result<()> {
        let index = self.cross_index.expect("only cross-attentions take image tokens");
        let (Some(layer), Some(&scale)) = (adapter.layers.get(index), adapter.scales.get(index)) else {
            return Err(Error::Config(format!(
                "IP-Adapter has {} layers but the UNet has more cross-attentions",
                adapter.layers.len()
            )));
        };
        if scale == 0.0 {
            return Ok(());
        }
        let (b, n, c) = (q.shape()[0], q.shape()[1], q.shape()[2]);
        let tokens = adapter.tokens.shape()[1];
        let k = g.project_conditioning(&layer.to_k_ip, &adapter.tokens, 1.0)?;
        let v = g.project_conditioning(&layer.to_v_ip, &adapter.tokens, scale)?;
        let image = g.alloc(&[b, n, c])?;
        ops::attention(
            &mut g.rec,
            q,
            &k,
            &v,
            &image,
            &AttentionLayout::dense(b, self.heads, self.head_dim, n, tokens),
            softmax_scale,
        )?;
        Ok(ops::add(&mut g.rec, out, &image, out)?)
    }
}

/// A cross-attention of the network: its width and its diffusers module name
/// (`up_blocks.0.attentions.1.transformer_blocks.0.attn2`).
#[derive(Clone, Debug, PartialEq)]
pub struct CrossAttention {
    pub channels: usize,
    pub name: String,
}
