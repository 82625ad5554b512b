//! The half the UNet and its ControlNet share: time and added embeddings, conv_in and the down
//! blocks, producing the skip tensors.

use crate::error::Result;
use crate::layers::attention::CrossAttention;
use crate::layers::nn::{Conv2d, Graph};
use crate::layers::resnet::NormSpec;
use crate::unet::config::UNetConfig;
use crate::unet::embeddings::Embeddings;
use crate::unet::unet_2d_blocks::{BlockShape, BlockSpec, Conditioning, DownBlock, MidBlock};
use crate::weights::Weights;
use vkdiff_runtime::ops;
use vkdiff_runtime::Tensor;

pub struct DownPath {
    pub spec: BlockSpec,
    conv_in: Conv2d,
    embeddings: Embeddings,
    blocks: Vec<DownBlock>,
}

/// What the down path leaves: the last hidden state, every skip in order, SiLU(embedding).
pub struct DownOutput {
    pub h: Tensor,
    pub skips: Vec<Tensor>,
    pub emb_silu: Tensor,
}

impl DownPath {
    /// Loads the down path, appending its cross-attentions' channels to `crosses`.
    pub fn load(w: &Weights, config: &UNetConfig, crosses: &mut Vec<CrossAttention>) -> Result<DownPath> {
        let levels = config.levels()?;
        let norm = NormSpec { groups: config.norm_num_groups, eps: config.norm_eps };
        let spec = BlockSpec { temb: config.time_embed_dim(), norm, context: config.cross_attention_dim };
        let c0 = config.block_out_channels[0];
        let mut blocks = Vec::new();
        for (i, level) in levels.iter().enumerate() {
            let shape = BlockShape {
                inputs: if i == 0 { c0 } else { levels[i - 1].channels },
                outputs: level.channels,
                layers: config.layers_per_block,
                attention: level.cross_attention.then_some((level.depth, level.heads)),
                resample: i + 1 < levels.len(),
            };
            blocks.push(DownBlock::load(&w.sub(&format!("down_blocks.{i}")), &shape, &spec, 1, crosses)?);
        }
        Ok(DownPath {
            conv_in: Conv2d::load(w, "conv_in", config.in_channels, c0, 3, 1, 1)?,
            embeddings: Embeddings::load(w, config)?,
            blocks,
            spec,
        })
    }

    /// The mid block at the bottom of this path.
    pub fn load_mid(&self, w: &Weights, config: &UNetConfig, crosses: &mut Vec<CrossAttention>) -> Result<MidBlock> {
        let last = config.levels()?.pop().expect("validated configs have levels");
        MidBlock::load(&w.sub("mid_block"), last.channels, last.depth, last.heads, &self.spec, crosses)
    }

    pub fn text_embeds_dim(&self) -> Option<usize> {
        self.embeddings.text_embeds_dim()
    }

    /// Runs the embeddings (plus `emb_add`), conv_in (plus `hint`, a ControlNet's encoded conditioning image) and
    /// the down blocks.
    pub fn forward(
        &self,
        g: &mut Graph,
        sample: &Tensor,
        timesteps: &Tensor,
        added: Option<(&Tensor, &Tensor)>,
        cond: &DownConditioning,
    ) -> Result<DownOutput> {
        let emb_silu = self.embeddings.forward(g, timesteps, added, cond.emb_add)?;
        let h = self.conv_in.forward(g, sample)?;
        if let Some(hint) = cond.hint {
            ops::add(&mut g.rec, &h, hint, &h)?;
        }
        let mut h = h;
        let mut skips = vec![h.clone()];
        let blocks = Conditioning { emb_silu: &emb_silu, context: cond.context, ip: cond.ip };
        for block in &self.blocks {
            h = block.forward(g, h, &blocks, &mut skips)?;
        }
        Ok(DownOutput { h, skips, emb_silu })
    }
}

/// The per-evaluation inputs of the down path beyond the sample and embeddings.
pub struct DownConditioning<'a> {
    pub context: &'a Tensor,
    pub ip: &'a [crate::layers::attention::IpAdapterInput],
    pub hint: Option<&'a Tensor>,
    /// Added to the time embedding before its SiLU: a ControlNet-Union's control embedding.
    pub emb_add: Option<&'a Tensor>,
}
