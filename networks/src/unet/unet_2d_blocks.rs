//! The UNet's blocks: `DownBlock2D` / `CrossAttnDownBlock2D`, `UNetMidBlock2DCrossAttn`,
//! `UpBlock2D` / `CrossAttnUpBlock2D` (a block without attention has an empty `attentions`).

use crate::error::Result;
use crate::layers::attention::CrossAttention;
use crate::layers::attention::IpAdapterInput;
use crate::layers::nn::Graph;
use crate::layers::resnet::{Downsample2D, NormSpec, ResnetBlock2D, Upsample2D};
use crate::layers::transformer_2d::{AttentionSpec, Transformer2DModel};
use crate::weights::Weights;
use vkdiff_runtime::ops;
use vkdiff_runtime::Tensor;

/// What the blocks share: time-embedding width, norms, attention settings, the conditioning.
pub struct BlockSpec {
    pub temb: usize,
    pub norm: NormSpec,
    pub context: usize,
}

/// Per-forward inputs every block reads.
pub struct Conditioning<'a> {
    pub emb_silu: &'a Tensor,
    pub context: &'a Tensor,
    pub ip: &'a [IpAdapterInput],
}

/// What one down or up block is built from.
pub struct BlockShape {
    pub inputs: usize,
    pub outputs: usize,
    pub layers: usize,
    /// Transformer depth; `None` for a block without attention.
    pub attention: Option<(usize, usize)>,
    pub resample: bool,
}

fn load_attentions(
    w: &Weights,
    shape: &BlockShape,
    spec: &BlockSpec,
    crosses: &mut Vec<CrossAttention>,
) -> Result<Vec<Transformer2DModel>> {
    let Some((depth, heads)) = shape.attention else { return Ok(Vec::new()) };
    let attn = AttentionSpec { heads, context: spec.context, groups: spec.norm.groups };
    (0..shape.layers)
        .map(|j| Transformer2DModel::load(&w.sub(&format!("attentions.{j}")), shape.outputs, depth, &attn, crosses))
        .collect()
}

pub struct DownBlock {
    resnets: Vec<ResnetBlock2D>,
    attentions: Vec<Transformer2DModel>,
    downsampler: Option<Downsample2D>,
}

impl DownBlock {
    pub fn load(
        w: &Weights,
        shape: &BlockShape,
        spec: &BlockSpec,
        padding: usize,
        crosses: &mut Vec<CrossAttention>,
    ) -> Result<DownBlock> {
        let resnets = (0..shape.layers)
            .map(|j| {
                let inputs = if j == 0 { shape.inputs } else { shape.outputs };
                ResnetBlock2D::load(&w.sub(&format!("resnets.{j}")), inputs, shape.outputs, Some(spec.temb), spec.norm)
            })
            .collect::<Result<Vec<_>>>()?;
        let attentions = load_attentions(w, shape, spec, crosses)?;
        let downsampler = if shape.resample {
            Some(Downsample2D::load(&w.sub("downsamplers.0"), shape.outputs, padding)?)
        } else {
            None
        };
        Ok(DownBlock { resnets, attentions, downsampler })
    }

    /// Runs the block, pushing every layer's output (and the downsampler's) onto `skips`.
    pub fn forward(
        &self,
        g: &mut Graph,
        mut h: Tensor,
        cond: &Conditioning,
        skips: &mut Vec<Tensor>,
    ) -> Result<Tensor> {
        for (j, resnet) in self.resnets.iter().enumerate() {
            h = resnet.forward(g, &h, Some(cond.emb_silu))?;
            if let Some(attn) = self.attentions.get(j) {
                h = attn.forward_consuming(g, h, cond.context, cond.ip)?;
            }
            skips.push(h.clone());
        }
        if let Some(down) = &self.downsampler {
            h = down.forward(g, &h)?;
            skips.push(h.clone());
        }
        Ok(h)
    }
}

pub struct MidBlock {
    resnet_0: ResnetBlock2D,
    attention: Transformer2DModel,
    resnet_1: ResnetBlock2D,
}

impl MidBlock {
    pub fn load(
        w: &Weights,
        channels: usize,
        depth: usize,
        heads: usize,
        spec: &BlockSpec,
        crosses: &mut Vec<CrossAttention>,
    ) -> Result<MidBlock> {
        let attn = AttentionSpec { heads, context: spec.context, groups: spec.norm.groups };
        Ok(MidBlock {
            resnet_0: ResnetBlock2D::load(&w.sub("resnets.0"), channels, channels, Some(spec.temb), spec.norm)?,
            attention: Transformer2DModel::load(&w.sub("attentions.0"), channels, depth, &attn, crosses)?,
            resnet_1: ResnetBlock2D::load(&w.sub("resnets.1"), channels, channels, Some(spec.temb), spec.norm)?,
        })
    }

    pub fn forward(&self, g: &mut Graph, h: &Tensor, cond: &Conditioning) -> Result<Tensor> {
        let h = self.resnet_0.forward(g, h, Some(cond.emb_silu))?;
        let h = self.attention.forward_consuming(g, h, cond.context, cond.ip)?;
        self.resnet_1.forward(g, &h, Some(cond.emb_silu))
    }
}

pub struct UpBlock {
    resnets: Vec<ResnetBlock2D>,
    attentions: Vec<Transformer2DModel>,
    upsampler: Option<Upsample2D>,
}

impl UpBlock {
    /// `shape.inputs` is the channel count of the down level this block mirrors, `prev` that of
    /// the hidden state arriving from below; resnet j concatenates a skip onto its input.
    pub fn load(
        w: &Weights,
        shape: &BlockShape,
        prev: usize,
        spec: &BlockSpec,
        crosses: &mut Vec<CrossAttention>,
    ) -> Result<UpBlock> {
        let resnets = (0..shape.layers)
            .map(|j| {
                let skip = if j + 1 == shape.layers { shape.inputs } else { shape.outputs };
                let hidden = if j == 0 { prev } else { shape.outputs };
                ResnetBlock2D::load(
                    &w.sub(&format!("resnets.{j}")),
                    hidden + skip,
                    shape.outputs,
                    Some(spec.temb),
                    spec.norm,
                )
            })
            .collect::<Result<Vec<_>>>()?;
        let attentions = load_attentions(w, shape, spec, crosses)?;
        let upsampler =
            if shape.resample { Some(Upsample2D::load(&w.sub("upsamplers.0"), shape.outputs)?) } else { None };
        Ok(UpBlock { resnets, attentions, upsampler })
    }

    /// Runs the block, taking its skips from the end of `skips` (last pushed first).
    pub fn forward(
        &self,
        g: &mut Graph,
        mut h: Tensor,
        cond: &Conditioning,
        skips: &mut Vec<Tensor>,
    ) -> Result<Tensor> {
        for (j, resnet) in self.resnets.iter().enumerate() {
            let skip = skips.pop().expect("the down path pushes one skip per up-block resnet");
            let s = h.shape();
            let joined = g.alloc(&[s[0], s[1], s[2], s[3] + skip.shape()[3]])?;
            ops::concat_channels(&mut g.rec, &h, &skip, &joined)?;
            drop(skip);
            h = resnet.forward(g, &joined, Some(cond.emb_silu))?;
            if let Some(attn) = self.attentions.get(j) {
                h = attn.forward_consuming(g, h, cond.context, cond.ip)?;
            }
        }
        if let Some(up) = &self.upsampler {
            h = up.forward(g, &h)?;
        }
        Ok(h)
    }
}
