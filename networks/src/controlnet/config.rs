//! A `ControlNetModel`'s config: the UNet encoder half it copies plus the conditioning-image
//! encoder, from a diffusers config.json or, for a single file, from the base UNet's config and
//! the file's shapes; and the original ("cldm") single-file names.

use crate::error::{Error, Result};
use crate::unet::config::UNetConfig;
use crate::weights::Checkpoint;
use crate::weights::{Inner, OriginalNames, StoredAs};
use serde::Deserialize;
use std::path::Path;
use vkdiff_formats::Error as FileError;

/// `diffusers/controlnet-depth-sdxl-1.0`'s config.json (reference/sdxl.md §6.1).
pub const SDXL_CONTROLNET_CONFIG: &str = r#"{
    "in_channels": 4, "conditioning_channels": 3, "block_out_channels": [320, 640, 1280],
    "down_block_types": ["DownBlock2D", "CrossAttnDownBlock2D", "CrossAttnDownBlock2D"],
    "mid_block_type": "UNetMidBlock2DCrossAttn", "layers_per_block": 2,
    "transformer_layers_per_block": [1, 2, 10], "attention_head_dim": [5, 10, 20],
    "cross_attention_dim": 2048, "use_linear_projection": true, "norm_num_groups": 32, "norm_eps": 1e-5,
    "flip_sin_to_cos": true, "freq_shift": 0, "addition_embed_type": "text_time",
    "addition_time_embed_dim": 256, "projection_class_embeddings_input_dim": 2816,
    "conditioning_embedding_out_channels": [16, 32, 96, 256], "controlnet_conditioning_channel_order": "rgb",
    "global_pool_conditions": false, "act_fn": "silu"
}"#;

fn default_conditioning_channels() -> usize {
    3
}
fn default_embedding_channels() -> Vec<usize> {
    vec![16, 32, 96, 256]
}
fn default_order() -> String {
    "rgb".into()
}

/// The keys a ControlNet config has beyond the UNet's.
#[derive(Deserialize)]
struct ConditioningKeys {
    #[serde(default = "default_conditioning_channels")]
    conditioning_channels: usize,
    #[serde(default = "default_embedding_channels")]
    conditioning_embedding_out_channels: Vec<usize>,
    #[serde(default = "default_order")]
    controlnet_conditioning_channel_order: String,
    #[serde(default)]
    global_pool_conditions: bool,
    /// ControlNet-Union's: its control types (the weights' `task_embedding` rows decide).
    num_control_type: Option<usize>,
    num_trans_layer: Option<usize>,
}

#[derive(Clone, Debug)]
pub struct ControlNetConfig {
    /// The encoder half as a UNet config (its up path mirrors the down path, unused).
    pub encoder: UNetConfig,
    /// Channels of the conditioning image (3).
    pub conditioning_channels: usize,
    /// Widths of the conditioning encoder's stages; each stage after the first halves the size.
    pub embedding_channels: Vec<usize>,
    /// The conditioning image's channels arrive reversed (`controlnet_conditioning_channel_order` bgr).
    pub bgr: bool,
    /// A ControlNet-Union's `num_control_type` when the config names it; the checkpoint's
    /// `task_embedding` is what makes a ControlNet a Union, and must agree.
    pub control_types: Option<usize>,
}

impl ControlNetConfig {
    pub fn from_json(text: &str, what: &str) -> Result<ControlNetConfig> {
        let bad = |e: serde_json::Error| Error::Config(format!("{what}: not a ControlNet config: {e}"));
        let mut json: serde_json::Value = serde_json::from_str(text).map_err(bad)?;
        let keys: ConditioningKeys = serde_json::from_value(json.clone()).map_err(bad)?;
        if keys.global_pool_conditions {
            return Err(Error::Config(format!(
                "{what}: `global_pool_conditions` true (shuffle-style ControlNets) is not supported"
            )));
        }
        let bgr = match keys.controlnet_conditioning_channel_order.as_str() {
            "rgb" => false,
            "bgr" => true,
            other => {
                return Err(Error::Config(format!(
                    "{what}: `controlnet_conditioning_channel_order` {other:?} is not rgb or bgr"
                )))
            }
        };
        if keys.num_trans_layer.is_some_and(|n| n != 1) {
            return Err(Error::Config(format!(
                "{what}: a ControlNet-Union with `num_trans_layer` {} is not supported (the published ones have 1)",
                keys.num_trans_layer.unwrap_or_default()
            )));
        }
        mirror_up_path(&mut json);
        let encoder: UNetConfig = serde_json::from_value(json).map_err(bad)?;
        let config = ControlNetConfig {
            encoder,
            conditioning_channels: keys.conditioning_channels,
            embedding_channels: keys.conditioning_embedding_out_channels,
            bgr,
            control_types: keys.num_control_type,
        };
        config.validate()?;
        Ok(config)
    }

    pub fn from_file(path: &Path) -> Result<ControlNetConfig> {
        let text = std::fs::read_to_string(path).map_err(|e| FileError::Io { path: path.to_path_buf(), source: e })?;
        Self::from_json(&text, &path.display().to_string())
    }

    fn validate(&self) -> Result<()> {
        self.encoder.validate()?;
        if self.embedding_channels.is_empty() {
            return Err(Error::Config("ControlNet config `conditioning_embedding_out_channels` is empty".into()));
        }
        Ok(())
    }

    /// Pixels of conditioning image per latent along each side.
    pub fn downscale(&self) -> usize {
        1 << (self.embedding_channels.len() - 1)
    }

    /// The config of a single-file ControlNet: the UNet it is for gives what shapes cannot tell
    /// (heads, norms, embeddings), the file gives the attention depth of each level and the
    /// conditioning encoder's widths.
    pub(crate) fn infer(base: &UNetConfig, ckpt: &Checkpoint) -> Result<ControlNetConfig> {
        let mut encoder = base.clone();
        let levels = encoder.levels()?;
        let depths: Vec<usize> = (0..levels.len())
            .map(|i| {
                (0..)
                    .take_while(|t| {
                        ckpt.stored_shape(&format!("down_blocks.{i}.attentions.0.transformer_blocks.{t}.norm1.weight"))
                            .is_some()
                    })
                    .count()
            })
            .collect();
        encoder.transformer_layers_per_block = crate::unet::config::PerLevel::Each(depths);
        encoder.reverse_transformer_layers_per_block = None;
        let shape = |name: &str| ckpt.stored_shape(&format!("controlnet_cond_embedding.{name}.weight"));
        let conv_in = shape("conv_in").ok_or_else(|| {
            Error::Checkpoint(
                "ControlNet file has no conditioning encoder (`controlnet_cond_embedding.conv_in` / \
                `input_hint_block.0`)"
                    .into(),
            )
        })?;
        let [out, conditioning_channels, _, _] = conv_in[..] else {
            return Err(Error::Checkpoint(format!(
                "the ControlNet's conditioning `conv_in` weight has shape {conv_in:?}, not a convolution's"
            )));
        };
        let mut embedding_channels = vec![out];
        // Blocks come in pairs: a same-width conv, then a stride-2 conv to the next width.
        while let Some(&width) =
            shape(&format!("blocks.{}", 2 * embedding_channels.len() - 1)).as_ref().and_then(|s| s.first())
        {
            embedding_channels.push(width);
        }
        let config =
            ControlNetConfig { encoder, conditioning_channels, embedding_channels, bgr: false, control_types: None };
        config.validate()?;
        Ok(config)
    }
}

/// A ControlNet config has no up path; the encoder is described by a UNet config whose up path
/// mirrors the down path so the shared validation and names apply.
fn mirror_up_path(json: &mut serde_json::Value) {
    let Some(obj) = json.as_object_mut() else { return };
    let up: Vec<serde_json::Value> = obj
        .get("down_block_types")
        .and_then(|d| d.as_array())
        .map(|d| d.iter().rev().map(|t| t.as_str().unwrap_or("").replace("Down", "Up").into()).collect())
        .unwrap_or_default();
    obj.entry("up_block_types").or_insert(up.into());
    let in_channels = obj.get("in_channels").cloned().unwrap_or(4.into());
    obj.entry("out_channels").or_insert(in_channels);
}

/// The original (cldm) names of a ControlNet: the UNet encoder's original names plus the hint
/// encoder (`input_hint_block`, SiLUs at the odd indices), `zero_convs` and `middle_block_out`.
pub(crate) fn cldm_names(encoder: &UNetConfig, embedding_stages: usize) -> Result<OriginalNames> {
    let mut names = crate::unet::unet_names(encoder)?;
    names.module("controlnet_cond_embedding.conv_in", "input_hint_block.0", Inner::Same);
    for k in 0..2 * (embedding_stages - 1) {
        names.module(
            &format!("controlnet_cond_embedding.blocks.{k}"),
            &format!("input_hint_block.{}", 2 * k + 2),
            Inner::Same,
        );
    }
    names.module(
        "controlnet_cond_embedding.conv_out",
        &format!("input_hint_block.{}", 4 * embedding_stages - 2),
        Inner::Same,
    );
    // One skip per resnet and per downsampler, plus conv_in's.
    let skips = encoder.block_out_channels.len() * (encoder.layers_per_block + 1);
    for k in 0..skips {
        names.module(&format!("controlnet_down_blocks.{k}"), &format!("zero_convs.{k}.0"), Inner::Same);
    }
    names.module("controlnet_mid_block", "middle_block_out.0", Inner::Same);
    // A Union's extras keep their diffusers names in the cldm layout too.
    for module in ["transformer_layes", "spatial_ch_projs", "control_add_embedding"] {
        names.module(module, module, Inner::Same);
    }
    names.tensor("task_embedding", StoredAs::plain("task_embedding".into()));
    Ok(names)
}
