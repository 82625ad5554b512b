//! The keys of a transformers `CLIPTextConfig` vkdiff reads, and SDXL base's two.

use crate::error::{Error, Result};
use serde::Deserialize;
use vkdiff_runtime::ops::UnaryOp;

fn default_positions() -> usize {
    77
}
fn default_act() -> String {
    "quick_gelu".into()
}
fn default_eps() -> f32 {
    1e-5
}
fn default_eos() -> u32 {
    2
}

/// SDXL base 1.0's text_encoder/config.json (CLIP ViT-L/14 text tower).
pub const SDXL_CLIP_L_CONFIG: &str = r#"{"vocab_size": 49408, "hidden_size": 768, "intermediate_size": 3072,
    "num_hidden_layers": 12, "num_attention_heads": 12, "max_position_embeddings": 77, "hidden_act": "quick_gelu",
    "layer_norm_eps": 1e-5, "eos_token_id": 2}"#;
/// SDXL base 1.0's text_encoder_2/config.json (OpenCLIP ViT-bigG/14 text tower with projection).
pub const SDXL_BIGG_CONFIG: &str = r#"{"vocab_size": 49408, "hidden_size": 1280, "intermediate_size": 5120,
    "num_hidden_layers": 32, "num_attention_heads": 20, "max_position_embeddings": 77, "hidden_act": "gelu",
    "layer_norm_eps": 1e-5, "projection_dim": 1280, "eos_token_id": 2}"#;

/// The keys of a transformers `CLIPTextConfig` (text_encoder/config.json) vkdiff reads.
#[derive(Clone, Debug, Deserialize)]
pub struct ClipTextConfig {
    pub vocab_size: usize,
    pub hidden_size: usize,
    pub intermediate_size: usize,
    pub num_hidden_layers: usize,
    pub num_attention_heads: usize,
    #[serde(default = "default_positions")]
    pub max_position_embeddings: usize,
    #[serde(default = "default_act")]
    pub hidden_act: String,
    #[serde(default = "default_eps")]
    pub layer_norm_eps: f32,
    #[serde(default)]
    pub projection_dim: Option<usize>,
    /// 2 (legacy configs) means "the EOS is the largest id", as transformers reads it.
    #[serde(default = "default_eos")]
    pub eos_token_id: u32,
}

impl ClipTextConfig {
    pub(crate) fn activation(&self) -> Result<UnaryOp> {
        match self.hidden_act.as_str() {
            "quick_gelu" => Ok(UnaryOp::QuickGelu),
            "gelu" => Ok(UnaryOp::Gelu),
            other => {
                Err(Error::Config(format!("text encoder `hidden_act` {other:?} is not supported (quick_gelu, gelu)")))
            }
        }
    }

    pub(crate) fn validate(&self) -> Result<()> {
        self.activation()?;
        let heads = self.num_attention_heads;
        if heads == 0 || !self.hidden_size.is_multiple_of(heads) {
            return Err(Error::Config(format!(
                "text encoder: {} channels do not split into {heads} heads",
                self.hidden_size
            )));
        }
        if self.num_hidden_layers < 2 {
            return Err(Error::Config(
                "text encoder: SDXL reads the penultimate layer, so it needs at least 2 layers".into(),
            ));
        }
        Ok(())
    }
}
