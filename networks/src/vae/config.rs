//! The keys of a diffusers `AutoencoderKL` config vkdiff reads, and SDXL base's.

use crate::error::{Error, Result};
use serde::Deserialize;

fn default_rgb() -> usize {
    3
}
fn default_one() -> usize {
    1
}
fn default_latent() -> usize {
    4
}
fn default_groups() -> usize {
    32
}
fn default_scale() -> f32 {
    0.18215
}
fn default_true() -> bool {
    true
}
fn default_act() -> String {
    "silu".into()
}
/// diffusers' default `sample_size`.
fn default_sample_size() -> SampleSize {
    SampleSize::Side(32)
}

/// `sample_size`: one side, or [height, width] (diffusers tiles by the first).
#[derive(Clone, Debug, Deserialize)]
#[serde(untagged)]
pub enum SampleSize {
    Side(usize),
    Sides(Vec<usize>),
}

/// SDXL base 1.0's vae/config.json.
pub const SDXL_VAE_CONFIG: &str = r#"{"in_channels": 3, "out_channels": 3, "block_out_channels": [128, 256, 512, 512],
    "down_block_types": ["DownEncoderBlock2D", "DownEncoderBlock2D", "DownEncoderBlock2D", "DownEncoderBlock2D"],
    "up_block_types": ["UpDecoderBlock2D", "UpDecoderBlock2D", "UpDecoderBlock2D", "UpDecoderBlock2D"],
    "layers_per_block": 2, "latent_channels": 4, "norm_num_groups": 32, "scaling_factor": 0.13025,
    "force_upcast": true, "sample_size": 1024}"#;

/// The keys of a diffusers `AutoencoderKL` config.json vkdiff reads.
#[derive(Clone, Debug, Deserialize)]
pub struct VaeConfig {
    #[serde(default = "default_rgb")]
    pub in_channels: usize,
    #[serde(default = "default_rgb")]
    pub out_channels: usize,
    pub block_out_channels: Vec<usize>,
    #[serde(default)]
    pub down_block_types: Vec<String>,
    #[serde(default)]
    pub up_block_types: Vec<String>,
    #[serde(default = "default_one")]
    pub layers_per_block: usize,
    #[serde(default = "default_latent")]
    pub latent_channels: usize,
    #[serde(default = "default_groups")]
    pub norm_num_groups: usize,
    #[serde(default = "default_scale")]
    pub scaling_factor: f32,
    #[serde(default)]
    pub shift_factor: Option<f32>,
    /// The VAE overflows f16 and must run in f32 (SDXL's original VAE).
    #[serde(default = "default_true")]
    pub force_upcast: bool,
    #[serde(default = "default_true")]
    pub mid_block_add_attention: bool,
    #[serde(default = "default_true")]
    pub use_quant_conv: bool,
    #[serde(default = "default_true")]
    pub use_post_quant_conv: bool,
    #[serde(default = "default_act")]
    pub act_fn: String,
    /// The image side the VAE was trained at: diffusers' default tile for a tiled decode.
    #[serde(default = "default_sample_size")]
    pub sample_size: SampleSize,
}

impl VaeConfig {
    pub(crate) fn validate(&self) -> Result<()> {
        let bad = |what: String| Err(Error::Config(format!("VAE config: {what}")));
        if self.block_out_channels.is_empty() || self.layers_per_block == 0 {
            return bad("no levels or no resnets per level".into());
        }
        if self.act_fn != "silu" {
            return bad(format!("`act_fn` {:?} is not supported (silu)", self.act_fn));
        }
        if let Some(t) = self
            .down_block_types
            .iter()
            .chain(&self.up_block_types)
            .find(|t| !matches!(t.as_str(), "DownEncoderBlock2D" | "UpDecoderBlock2D"))
        {
            return bad(format!("block type {t:?} is not supported"));
        }
        if self.block_out_channels.iter().any(|c| {
            !c.is_multiple_of(self.norm_num_groups) || !c.is_multiple_of(4) || *c > 512 && self.mid_block_add_attention
        }) {
            return bad(format!(
                "channels {:?} must be multiples of 4 and of {} groups, at most 512 with mid attention",
                self.block_out_channels, self.norm_num_groups
            ));
        }
        Ok(())
    }

    /// diffusers' default tile side for a tiled decode (`tile_sample_min_size`), in pixels.
    pub fn tile_sample_size(&self) -> usize {
        match &self.sample_size {
            SampleSize::Side(side) => *side,
            SampleSize::Sides(sides) => sides.first().copied().unwrap_or(32),
        }
    }

    /// Pixels per latent along each side.
    pub fn downscale(&self) -> usize {
        1 << (self.block_out_channels.len() - 1)
    }
}
