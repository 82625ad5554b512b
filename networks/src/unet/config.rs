//! `UNet2DConditionModel`'s config.json, the subset SDXL-family UNets use, with the per-level
//! values derived the way diffusers derives them.

use crate::error::{Error, Result};
use crate::layers::attention::CrossAttention;
use crate::weights::read_config;
use serde::Deserialize;
use std::path::Path;

/// An int for every level, or one value per level (diffusers accepts both).
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(untagged)]
pub enum PerLevel {
    One(usize),
    Each(Vec<usize>),
}

impl PerLevel {
    fn resolve(&self, levels: usize, key: &str) -> Result<Vec<usize>> {
        match self {
            PerLevel::One(v) => Ok(vec![*v; levels]),
            PerLevel::Each(v) if v.len() == levels => Ok(v.clone()),
            PerLevel::Each(v) => {
                Err(Error::Config(format!("config `{key}` has {} entries for {levels} levels", v.len())))
            }
        }
    }
}

fn default_true() -> bool {
    true
}
fn default_groups() -> usize {
    32
}
fn default_eps() -> f32 {
    1e-5
}
fn default_layers() -> PerLevel {
    PerLevel::One(1)
}
fn default_heads() -> PerLevel {
    PerLevel::One(8)
}
fn default_act() -> String {
    "silu".into()
}

/// The settings of a diffusers `UNet2DConditionModel` config.json that vkdiff reads. Keys it
/// does not support with other values than SDXL's are checked by [`UNetConfig::validate`].
#[derive(Clone, Debug, Deserialize)]
pub struct UNetConfig {
    pub in_channels: usize,
    pub out_channels: usize,
    pub block_out_channels: Vec<usize>,
    pub down_block_types: Vec<String>,
    pub up_block_types: Vec<String>,
    #[serde(default)]
    pub mid_block_type: Option<String>,
    pub layers_per_block: usize,
    #[serde(default = "default_layers")]
    pub transformer_layers_per_block: PerLevel,
    #[serde(default)]
    pub reverse_transformer_layers_per_block: Option<Vec<usize>>,
    /// The number of heads per level when `num_attention_heads` is null (diffusers' misnomer).
    #[serde(default = "default_heads")]
    pub attention_head_dim: PerLevel,
    #[serde(default)]
    pub num_attention_heads: Option<PerLevel>,
    pub cross_attention_dim: usize,
    #[serde(default)]
    pub use_linear_projection: bool,
    #[serde(default = "default_groups")]
    pub norm_num_groups: usize,
    #[serde(default = "default_eps")]
    pub norm_eps: f32,
    #[serde(default = "default_true")]
    pub flip_sin_to_cos: bool,
    #[serde(default)]
    pub freq_shift: f32,
    #[serde(default)]
    pub addition_embed_type: Option<String>,
    #[serde(default)]
    pub addition_time_embed_dim: Option<usize>,
    #[serde(default)]
    pub projection_class_embeddings_input_dim: Option<usize>,
    #[serde(default = "default_act")]
    pub act_fn: String,
    #[serde(default)]
    pub class_embed_type: Option<String>,
    #[serde(default)]
    pub encoder_hid_dim: Option<usize>,
    #[serde(default)]
    pub time_cond_proj_dim: Option<usize>,
    #[serde(default)]
    pub time_embedding_dim: Option<usize>,
    #[serde(default)]
    pub center_input_sample: bool,
    #[serde(default)]
    pub upcast_attention: bool,
    #[serde(default)]
    pub dual_cross_attention: bool,
    #[serde(default)]
    pub resnet_time_scale_shift: Option<String>,
}

/// One level of the UNet as the blocks are built: channels, attention depth and heads.
#[derive(Clone, Debug)]
pub struct Level {
    pub channels: usize,
    pub cross_attention: bool,
    pub depth: usize,
    pub heads: usize,
}

/// `stabilityai/stable-diffusion-xl-base-1.0`'s unet/config.json (reference/sdxl.md §1.1).
pub const SDXL_BASE_CONFIG: &str = r#"{
    "in_channels": 4, "out_channels": 4, "block_out_channels": [320, 640, 1280],
    "down_block_types": ["DownBlock2D", "CrossAttnDownBlock2D", "CrossAttnDownBlock2D"],
    "up_block_types": ["CrossAttnUpBlock2D", "CrossAttnUpBlock2D", "UpBlock2D"],
    "mid_block_type": "UNetMidBlock2DCrossAttn", "layers_per_block": 2,
    "transformer_layers_per_block": [1, 2, 10], "attention_head_dim": [5, 10, 20],
    "cross_attention_dim": 2048, "use_linear_projection": true, "norm_num_groups": 32, "norm_eps": 1e-5,
    "flip_sin_to_cos": true, "freq_shift": 0, "addition_embed_type": "text_time",
    "addition_time_embed_dim": 256, "projection_class_embeddings_input_dim": 2816,
    "act_fn": "silu", "sample_size": 128
}"#;

impl UNetConfig {
    /// SDXL base 1.0's UNet (2.57 B parameters).
    pub fn sdxl_base() -> UNetConfig {
        serde_json::from_str(SDXL_BASE_CONFIG).expect("built-in config parses")
    }

    pub fn from_file(path: &Path) -> Result<UNetConfig> {
        let config: UNetConfig = read_config(path, "a UNet")?;
        config.validate()?;
        Ok(config)
    }

    /// Rejects settings this implementation does not build, naming the key.
    pub fn validate(&self) -> Result<()> {
        let unsupported =
            |key: &str, value: String| Err(Error::Config(format!("config `{key}` = {value} is not supported")));
        let levels = self.block_out_channels.len();
        if levels == 0 || self.down_block_types.len() != levels || self.up_block_types.len() != levels {
            return Err(Error::Config(format!(
                "config lists {} block_out_channels, {} down and {} up block types; they must match",
                levels,
                self.down_block_types.len(),
                self.up_block_types.len()
            )));
        }
        for t in &self.down_block_types {
            if t != "DownBlock2D" && t != "CrossAttnDownBlock2D" {
                return unsupported("down_block_types", t.clone());
            }
        }
        for t in &self.up_block_types {
            if t != "UpBlock2D" && t != "CrossAttnUpBlock2D" {
                return unsupported("up_block_types", t.clone());
            }
        }
        if let Some(t) = self.mid_block_type.as_deref().filter(|t| *t != "UNetMidBlock2DCrossAttn") {
            return unsupported("mid_block_type", t.into());
        }
        if self.act_fn != "silu" {
            return unsupported("act_fn", self.act_fn.clone());
        }
        if let Some(t) = self.addition_embed_type.as_deref().filter(|t| *t != "text_time") {
            return unsupported("addition_embed_type", t.into());
        }
        if self.addition_embed_type.is_some()
            && (self.addition_time_embed_dim.is_none() || self.projection_class_embeddings_input_dim.is_none())
        {
            return Err(Error::Config(
                "config `addition_embed_type` text_time needs addition_time_embed_dim and \
                projection_class_embeddings_input_dim"
                    .into(),
            ));
        }
        for (key, set) in [
            ("class_embed_type", self.class_embed_type.is_some()),
            ("encoder_hid_dim", self.encoder_hid_dim.is_some()),
            ("time_cond_proj_dim", self.time_cond_proj_dim.is_some()),
            ("center_input_sample", self.center_input_sample),
            ("dual_cross_attention", self.dual_cross_attention),
        ] {
            if set {
                return unsupported(key, "set".into());
            }
        }
        if let Some(s) = self.resnet_time_scale_shift.as_deref().filter(|s| *s != "default") {
            return unsupported("resnet_time_scale_shift", s.into());
        }
        let levels = self.levels()?;
        for l in levels.iter().filter(|l| l.cross_attention || l.depth > 0) {
            if l.heads == 0 || !l.channels.is_multiple_of(l.heads) {
                return Err(Error::Config(format!("{} channels do not split into {} heads", l.channels, l.heads)));
            }
        }
        for c in &self.block_out_channels {
            if *c == 0 || !c.is_multiple_of(self.norm_num_groups) {
                return Err(Error::Config(format!(
                    "{c} channels do not split into norm_num_groups = {}",
                    self.norm_num_groups
                )));
            }
        }
        Ok(())
    }

    /// The down path's levels, in order.
    pub fn levels(&self) -> Result<Vec<Level>> {
        let n = self.block_out_channels.len();
        let depth = self.transformer_layers_per_block.resolve(n, "transformer_layers_per_block")?;
        let heads =
            self.num_attention_heads.as_ref().unwrap_or(&self.attention_head_dim).resolve(n, "attention_head_dim")?;
        Ok((0..n)
            .map(|i| Level {
                channels: self.block_out_channels[i],
                cross_attention: self.down_block_types[i] == "CrossAttnDownBlock2D",
                depth: depth[i],
                heads: heads[i],
            })
            .collect())
    }

    /// Attention depth of each up block (reverse level order).
    pub fn up_depths(&self) -> Result<Vec<usize>> {
        let levels = self.levels()?;
        match &self.reverse_transformer_layers_per_block {
            Some(v) if v.len() == levels.len() => Ok(v.clone()),
            Some(v) => Err(Error::Config(format!(
                "config `reverse_transformer_layers_per_block` has {} entries for {} levels",
                v.len(),
                levels.len()
            ))),
            None => Ok(levels.iter().rev().map(|l| l.depth).collect()),
        }
    }

    /// The cross-attentions [`crate::UNet::load`] builds, in the same order (down blocks, up
    /// blocks, then the mid block: diffusers' processor order), without loading anything.
    pub fn cross_attentions(&self) -> Result<Vec<CrossAttention>> {
        let levels = self.levels()?;
        let up_depths = self.up_depths()?;
        let last = levels.last().ok_or_else(|| Error::Config("config has no levels".into()))?;
        let mut blocks: Vec<(String, usize, usize, usize)> = Vec::new();
        for (i, l) in levels.iter().enumerate().filter(|(_, l)| l.cross_attention) {
            blocks.push((format!("down_blocks.{i}"), self.layers_per_block, l.depth, l.channels));
        }
        for (i, _) in self.up_block_types.iter().enumerate().filter(|(_, t)| *t == "CrossAttnUpBlock2D") {
            blocks.push((
                format!("up_blocks.{i}"),
                self.layers_per_block + 1,
                up_depths[i],
                levels[levels.len() - 1 - i].channels,
            ));
        }
        blocks.push(("mid_block".into(), 1, last.depth, last.channels));
        Ok(blocks
            .into_iter()
            .flat_map(|(block, attentions, depth, channels)| {
                (0..attentions).flat_map(move |j| {
                    let block = block.clone();
                    (0..depth).map(move |t| CrossAttention {
                        channels,
                        name: format!("{block}.attentions.{j}.transformer_blocks.{t}.attn2"),
                    })
                })
            })
            .collect())
    }

    /// Width of the time embedding (4 × the first level's channels unless set).
    pub fn time_embed_dim(&self) -> usize {
        self.time_embedding_dim.unwrap_or(4 * self.block_out_channels[0])
    }
}
