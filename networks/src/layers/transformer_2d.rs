//! diffusers `Transformer2DModel` (continuous input) and `BasicTransformerBlock` with GEGLU.

use crate::error::Result;
use crate::layers::attention::{Attention, CrossAttention, IpAdapterInput};
use crate::layers::nn::{with_last, Graph, GroupNorm, LayerNorm, Linear};
use crate::weights::Weights;
use vkdiff_runtime::ops;
use vkdiff_runtime::Tensor;

/// What a transformer's blocks attend with.
pub struct AttentionSpec {
    pub heads: usize,
    pub context: usize,
    pub groups: usize,
}

pub struct BasicTransformerBlock {
    norm1: LayerNorm,
    attn1: Attention,
    norm2: LayerNorm,
    attn2: Attention,
    norm3: LayerNorm,
    ff_in: Linear,
    ff_out: Linear,
}

impl BasicTransformerBlock {
    fn load(w: &Weights, c: usize, spec: &AttentionSpec, cross_index: usize) -> Result<BasicTransformerBlock> {
        Ok(BasicTransformerBlock {
            norm1: LayerNorm::load(w, "norm1", c, 1e-5)?,
            attn1: Attention::load_self(&w.sub("attn1"), c, spec.heads)?,
            norm2: LayerNorm::load(w, "norm2", c, 1e-5)?,
            attn2: Attention::load_cross(&w.sub("attn2"), c, spec.context, spec.heads, cross_index)?,
            norm3: LayerNorm::load(w, "norm3", c, 1e-5)?,
            ff_in: Linear::load(w, "ff.net.0.proj", c, 8 * c, true)?,
            ff_out: Linear::load(w, "ff.net.2", 4 * c, c, true)?,
        })
    }

    /// Updates the token stream h[B, N, C] in place.
    fn forward(&self, g: &mut Graph, h: &Tensor, context: &Tensor, ip: &[IpAdapterInput]) -> Result<()> {
        let n = self.norm1.forward(g, h)?;
        self.attn1.forward_residual(g, &n, None, &[], h)?;
        let n = self.norm2.forward(g, h)?;
        self.attn2.forward_residual(g, &n, Some(context), ip, h)?;
        let n = self.norm3.forward(g, h)?;
        let gated = g.alloc(&with_last(n.shape(), self.ff_in.outputs() / 2))?;
        ops::linear_geglu(&mut g.rec, (&n, &self.ff_in.weight, self.ff_in.bias.as_ref()), &gated, &g.arena)?;
        self.ff_out.forward_into(g, &gated, h, true, 1.0)
    }
}

pub struct Transformer2DModel {
    norm: GroupNorm,
    proj_in: Linear,
    blocks: Vec<BasicTransformerBlock>,
    proj_out: Linear,
}

impl Transformer2DModel {
    /// Loads `depth` blocks; their cross-attentions are appended to `crosses` (in diffusers'
    /// processor order), their index being their position there.
    pub fn load(
        w: &Weights,
        c: usize,
        depth: usize,
        spec: &AttentionSpec,
        crosses: &mut Vec<CrossAttention>,
    ) -> Result<Transformer2DModel> {
        let blocks = (0..depth)
            .map(|t| {
                let block = w.sub(&format!("transformer_blocks.{t}"));
                crosses.push(CrossAttention { channels: c, name: block.sub("attn2").prefix().to_string() });
                BasicTransformerBlock::load(&block, c, spec, crosses.len() - 1)
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Transformer2DModel {
            norm: GroupNorm::load(w, "norm", c, spec.groups, 1e-6)?,
            // Linear projections, or 1×1 convolutions (use_linear_projection = false) read as such.
            proj_in: Linear::load(w, "proj_in", c, c, true)?,
            blocks,
            proj_out: Linear::load(w, "proj_out", c, c, true)?,
        })
    }

    /// x[B, H, W, C] → x + proj_out(blocks(proj_in(norm(x)))), written into x, which the caller
    /// hands over (no other tensor may share its buffer).
    pub fn forward_consuming(
        &self,
        g: &mut Graph,
        x: Tensor,
        context: &Tensor,
        ip: &[IpAdapterInput],
    ) -> Result<Tensor> {
        let s = x.shape().to_vec();
        let tokens = x.reshape(&[s[0], s[1] * s[2], s[3]])?;
        let h = self.norm.forward(g, &tokens, false)?;
        let h = self.proj_in.forward(g, &h)?;
        for block in &self.blocks {
            block.forward(g, &h, context, ip)?;
        }
        self.proj_out.forward_into(g, &h, &tokens, true, 1.0)?;
        Ok(x)
    }
}
