//! IP-Adapter Plus' perceiver `Resampler` (diffusers `IPAdapterPlusImageProjection`): learned
//! query latents cross-attend to the image encoder's penultimate tokens, giving the adapter's
//! image tokens. Read from the original file layout (`image_proj.layers.L.0.to_kv`, …).

use crate::error::{Error, Result};
use crate::layers::nn::{Graph, LayerNorm, Linear};
use crate::weights::Weights;
use std::collections::BTreeMap;
use vkdiff_runtime::ops::{self, AttentionLayout, UnaryOp};
use vkdiff_runtime::{Context, Dtype, Tensor};

/// diffusers' converter fixes the head size and derives the head count from `to_q`.
const HEAD_DIM: usize = 64;
/// nn.LayerNorm's default, used by every norm of the resampler.
const EPS: f32 = 1e-5;

/// Sizes read from the stored shapes.
#[derive(Clone, Debug)]
pub struct ResamplerDims {
    /// Encoder feature width (`proj_in` inputs).
    pub embed_dims: usize,
    /// Latent width.
    pub hidden_dims: usize,
    /// Output width, the UNet's cross_attention_dim.
    pub output_dims: usize,
    pub queries: usize,
    pub depth: usize,
    pub heads: usize,
    pub ff_dims: usize,
}

impl ResamplerDims {
    /// From the shapes of the `image_proj.*` tensors (names without the prefix).
    pub fn infer(shapes: &BTreeMap<String, Vec<usize>>) -> Result<ResamplerDims> {
        let shape = |name: &str, rank: usize| -> Result<&[usize]> {
            let s = shapes
                .get(name)
                .ok_or_else(|| Error::Checkpoint(format!("IP-Adapter Plus: tensor `image_proj.{name}` is missing")))?;
            if s.len() != rank {
                return Err(Error::Checkpoint(format!(
                    "IP-Adapter Plus: tensor `image_proj.{name}` has shape {s:?}, expected rank {rank}"
                )));
            }
            Ok(s)
        };
        let latents = shape("latents", 3)?;
        let proj_in = shape("proj_in.weight", 2)?;
        let proj_out = shape("proj_out.weight", 2)?;
        let to_q = shape("layers.0.0.to_q.weight", 2)?;
        let ff = shape("layers.0.1.1.weight", 2)?;
        let depth = (0..).take_while(|l| shapes.contains_key(&format!("layers.{l}.0.to_q.weight"))).count();
        if !to_q[0].is_multiple_of(HEAD_DIM) {
            return Err(Error::Checkpoint(format!(
                "IP-Adapter Plus: `to_q` has {} rows, not a whole number of {HEAD_DIM}-wide heads",
                to_q[0]
            )));
        }
        Ok(ResamplerDims {
            embed_dims: proj_in[1],
            hidden_dims: latents[2],
            output_dims: proj_out[0],
            queries: latents[1],
            depth,
            heads: to_q[0] / HEAD_DIM,
            ff_dims: ff[0],
        })
    }
}

/// `PerceiverAttention` + feed-forward, one resampler layer.
struct Block {
    /// Norm of the image features (diffusers `ln0`).
    norm1: LayerNorm,
    /// Norm of the latents (diffusers `ln1`).
    norm2: LayerNorm,
    to_q: Linear,
    /// k and v stacked: [2·inner, hidden].
    to_kv: Linear,
    to_out: Linear,
    ff_norm: LayerNorm,
    ff_in: Linear,
    ff_out: Linear,
}

impl Block {
    fn load(w: &Weights, d: &ResamplerDims) -> Result<Block> {
        let (h, inner) = (d.hidden_dims, d.heads * HEAD_DIM);
        let (attn, ff) = (w.sub("0"), w.sub("1"));
        Ok(Block {
            norm1: LayerNorm::load(&attn, "norm1", h, EPS)?,
            norm2: LayerNorm::load(&attn, "norm2", h, EPS)?,
            to_q: Linear::load(&attn, "to_q", h, inner, false)?,
            to_kv: Linear::load(&attn, "to_kv", h, 2 * inner, false)?,
            to_out: Linear::load(&attn, "to_out", inner, h, false)?,
            ff_norm: LayerNorm::load(&ff, "0", h, EPS)?,
            ff_in: Linear::load(&ff, "1", h, d.ff_dims, false)?,
            ff_out: Linear::load(&ff, "3", d.ff_dims, h, false)?,
        })
    }

    /// latents[B, Q, h] += attention(latents, [features; latents]), then += FF(latents).
    fn forward(&self, g: &mut Graph, x: &Tensor, latents: &Tensor, heads: usize) -> Result<()> {
        let (b, n, h) = (x.shape()[0], x.shape()[1], x.shape()[2]);
        let q_tokens = latents.shape()[1];
        let inner = heads * HEAD_DIM;
        let xn = self.norm1.forward(g, x)?;
        let ln = self.norm2.forward(g, latents)?;
        // Keys and values come from the features and the latents together, per image.
        let both = g.alloc(&[b, n + q_tokens, h])?;
        ops::concat_channels(
            &mut g.rec,
            &xn.reshape(&[b, n * h])?,
            &ln.reshape(&[b, q_tokens * h])?,
            &both.reshape(&[b, (n + q_tokens) * h])?,
        )?;
        let q = self.to_q.forward(g, &ln)?;
        let kv = self.to_kv.forward(g, &both)?;
        let kv_tokens = n + q_tokens;
        let mut l = AttentionLayout::dense(b, heads, HEAD_DIM, q_tokens, kv_tokens);
        (l.k_ld, l.v_ld) = (2 * inner, 2 * inner);
        (l.k_batch, l.v_batch) = (2 * inner * kv_tokens, 2 * inner * kv_tokens);
        l.v_offset = inner;
        let attn = g.alloc(&[b, q_tokens, inner])?;
        ops::attention(&mut g.rec, &q, &kv, &kv, &attn, &l, 1.0 / (HEAD_DIM as f32).sqrt())?;
        self.to_out.forward_into(g, &attn, latents, true, 1.0)?;
        let f = self.ff_norm.forward(g, latents)?;
        let f = self.ff_in.forward(g, &f)?;
        ops::unary(&mut g.rec, UnaryOp::Gelu, &f, &f, 1.0)?;
        self.ff_out.forward_into(g, &f, latents, true, 1.0)
    }
}

pub struct Resampler {
    dims: ResamplerDims,
    /// [queries, hidden] on the host, repeated per image.
    latents: Vec<f32>,
    proj_in: Linear,
    layers: Vec<Block>,
    proj_out: Linear,
    norm_out: LayerNorm,
}

impl Resampler {
    /// From the view `image_proj` of an adapter file.
    pub fn load(w: &Weights, dims: ResamplerDims) -> Result<Resampler> {
        let d = &dims;
        Ok(Resampler {
            latents: w.host("latents", &[1, d.queries, d.hidden_dims])?,
            proj_in: Linear::load(w, "proj_in", d.embed_dims, d.hidden_dims, true)?,
            layers: (0..d.depth)
                .map(|l| Block::load(&w.sub("layers").sub(&l.to_string()), d))
                .collect::<Result<_>>()?,
            proj_out: Linear::load(w, "proj_out", d.hidden_dims, d.output_dims, true)?,
            norm_out: LayerNorm::load(w, "norm_out", d.output_dims, EPS)?,
            dims,
        })
    }

    pub fn dims(&self) -> &ResamplerDims {
        &self.dims
    }

    /// features [B, N, embed_dims] → image tokens [B, queries, output_dims].
    pub fn forward(
        &self,
        ctx: &Context,
        dtype: Dtype,
        features: &[f32],
        batch: usize,
        tokens: usize,
    ) -> Result<Vec<f32>> {
        let d = &self.dims;
        let mut g = Graph::new(ctx, dtype)?;
        let x = ctx.upload(&[batch, tokens, d.embed_dims], dtype, features)?;
        let x = self.proj_in.forward(&mut g, &x)?;
        let latents = ctx.upload(&[batch, d.queries, d.hidden_dims], dtype, &self.latents.repeat(batch))?;
        for layer in &self.layers {
            layer.forward(&mut g, &x, &latents, d.heads)?;
        }
        let out = self.proj_out.forward(&mut g, &latents)?;
        let out = self.norm_out.forward(&mut g, &out)?;
        g.rec.finish()?.run()?;
        Ok(out.download()?)
    }
}
