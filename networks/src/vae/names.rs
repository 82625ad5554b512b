//! The VAE in single files: the original layout's renaming from diffusers names (whole SDXL
//! checkpoints under `first_stage_model.*`, and VAE files such as `sdxl_vae.safetensors`), VAE
//! files in diffusers' names, and the config read back from shapes.

use crate::error::{Error, Result};
use crate::vae::config::VaeConfig;
use crate::weights::{Inner, OriginalNames, StoredAs};
use std::collections::BTreeSet;
use vkdiff_formats::SafeTensors;

pub const SINGLE_FILE_VAE: &str = "first_stage_model.";

const RESNET: [(&str, &str); 1] = [("conv_shortcut", "nin_shortcut")];
/// Mid-block attention: diffusers name → original (1×1 convs there, linears here).
const ATTENTION: [(&str, &str); 5] =
    [("group_norm", "norm"), ("to_q", "q"), ("to_k", "k"), ("to_v", "v"), ("to_out.0", "proj_out")];

/// diffusers VAE names → original ones; the decoder's levels are numbered in reverse there.
pub fn vae_names(config: &VaeConfig) -> OriginalNames {
    let mut n = OriginalNames::keeping_others();
    let levels = config.block_out_channels.len();
    for side in ["encoder", "decoder"] {
        n.module(&format!("{side}.mid_block.resnets.0"), &format!("{side}.mid.block_1"), Inner::Table(&RESNET));
        n.module(&format!("{side}.mid_block.resnets.1"), &format!("{side}.mid.block_2"), Inner::Table(&RESNET));
        for (d, o) in ATTENTION {
            for kind in ["weight", "bias"] {
                n.tensor(
                    &format!("{side}.mid_block.attentions.0.{d}.{kind}"),
                    StoredAs::plain(format!("{side}.mid.attn_1.{o}.{kind}")),
                );
            }
        }
        n.module(&format!("{side}.conv_norm_out"), &format!("{side}.norm_out"), Inner::Same);
    }
    for i in 0..levels {
        let up = levels - 1 - i;
        for j in 0..=config.layers_per_block {
            n.module(
                &format!("encoder.down_blocks.{i}.resnets.{j}"),
                &format!("encoder.down.{i}.block.{j}"),
                Inner::Table(&RESNET),
            );
            n.module(
                &format!("decoder.up_blocks.{i}.resnets.{j}"),
                &format!("decoder.up.{up}.block.{j}"),
                Inner::Table(&RESNET),
            );
        }
        n.module(
            &format!("encoder.down_blocks.{i}.downsamplers.0"),
            &format!("encoder.down.{i}.downsample"),
            Inner::Same,
        );
        n.module(&format!("decoder.up_blocks.{i}.upsamplers.0"), &format!("decoder.up.{up}.upsample"), Inner::Same);
    }
    n
}

/// Where a single file keeps its VAE: under `first_stage_model.` in a whole SDXL checkpoint, at
/// the top of a VAE file; named as the original code names them, or as diffusers does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SingleFileVae {
    pub prefix: &'static str,
    pub diffusers_names: bool,
}

impl SingleFileVae {
    /// How `file` stores its VAE.
    pub fn of(file: &SafeTensors) -> SingleFileVae {
        // A whole checkpoint (its UNet under `model.diffusion_model.`) keeps the VAE under its prefix.
        let whole =
            file.entries.keys().any(|k| k.starts_with(SINGLE_FILE_VAE) || k.starts_with("model.diffusion_model."));
        let prefix = if whole { SINGLE_FILE_VAE } else { "" };
        let diffusers_names = file.entries.keys().any(|k| k.starts_with(&format!("{prefix}decoder.up_blocks.")));
        SingleFileVae { prefix, diffusers_names }
    }

    /// The stored name of the tensor the original layout calls `name` (only the names the
    /// config is read from).
    fn stored(&self, name: &str) -> String {
        if !self.diffusers_names {
            return format!("{}{name}", self.prefix);
        }
        let renamed = name
            .replace("encoder.down.", "encoder.down_blocks.")
            .replace(".block.", ".resnets.")
            .replace("decoder.mid.attn_1.q.", "decoder.mid_block.attentions.0.to_q.");
        format!("{}{renamed}", self.prefix)
    }
}

/// A VAE config from single-file shapes. The scaling factor (0.13025), 32 norm groups and
/// forced f32 are SDXL's, which shapes cannot show.
pub fn infer_vae_config(file: &SafeTensors, layout: SingleFileVae) -> Result<VaeConfig> {
    let shape = |name: &str| {
        let stored = layout.stored(name);
        file.entries.get(&stored).map(|e| e.shape.clone()).ok_or_else(|| {
            Error::Checkpoint(format!("{}: no tensor `{stored}`; not a single file with a VAE", file.path.display()))
        })
    };
    let dim = |name: &str, i: usize| {
        let s = shape(name)?;
        s.get(i).copied().ok_or_else(|| {
            Error::Checkpoint(format!(
                "{}: tensor `{}` has shape {s:?}; a weight there has more dimensions",
                file.path.display(),
                layout.stored(name)
            ))
        })
    };
    let indices = |prefix: &str| -> BTreeSet<usize> {
        let p = layout.stored(prefix);
        file.entries.keys().filter_map(|k| k.strip_prefix(&p)?.split('.').next()?.parse().ok()).collect()
    };
    let levels = indices("encoder.down.").len();
    let channels =
        (0..levels).map(|i| dim(&format!("encoder.down.{i}.block.0.conv1.weight"), 0)).collect::<Result<Vec<_>>>()?;
    let has = |name: &str| file.entries.contains_key(&layout.stored(name));
    let config = serde_json::json!({
        "in_channels": dim("encoder.conv_in.weight", 1)?,
        "out_channels": dim("decoder.conv_out.weight", 0)?,
        "block_out_channels": channels,
        "layers_per_block": indices("encoder.down.0.block.").len(),
        "latent_channels": dim("decoder.conv_in.weight", 1)?,
        "scaling_factor": 0.13025,
        "force_upcast": true,
        "mid_block_add_attention": has("decoder.mid.attn_1.q.weight"),
        "use_quant_conv": has("quant_conv.weight"),
        "use_post_quant_conv": has("post_quant_conv.weight"),
    });
    serde_json::from_value(config)
        .map_err(|e| Error::Checkpoint(format!("{}: VAE config from shapes: {e}", file.path.display())))
}
