//! A UNet in the original (sgm / LDM) single-file layout: the renaming from diffusers names
//! (generalised to any number of levels and resnets per block) and the config read back from
//! tensor shapes.

use crate::error::{Error, Result};
use crate::unet::config::UNetConfig;
use crate::weights::{Inner, OriginalNames};
use std::collections::{BTreeSet, HashMap};

/// Resnet submodules: diffusers name → original name.
const RESNET: [(&str, &str); 6] = [
    ("norm1", "in_layers.0"),
    ("conv1", "in_layers.2"),
    ("time_emb_proj", "emb_layers.1"),
    ("norm2", "out_layers.0"),
    ("conv2", "out_layers.3"),
    ("conv_shortcut", "skip_connection"),
];

/// Channels per head sgm's SDXL configs use (`num_head_channels: 64`); shapes cannot tell.
const HEAD_CHANNELS: usize = 64;
/// Width of each of the six size/crop embeddings in SDXL's added conditioning.
const TIME_ID_DIM: usize = 256;

/// The renaming of a UNet with `config` onto the original layout.
pub fn unet_names(config: &UNetConfig) -> Result<OriginalNames> {
    let l = config.layers_per_block;
    let levels = config.levels()?.len();
    let mut names = OriginalNames::default();
    let mut add = |d: String, o: String, resnet: bool| {
        names.module(&d, &o, if resnet { Inner::Strict(&RESNET) } else { Inner::Same })
    };
    for (d, o) in [
        ("time_embedding.linear_1", "time_embed.0"),
        ("time_embedding.linear_2", "time_embed.2"),
        ("add_embedding.linear_1", "label_emb.0.0"),
        ("add_embedding.linear_2", "label_emb.0.2"),
        ("conv_in", "input_blocks.0.0"),
        ("conv_norm_out", "out.0"),
        ("conv_out", "out.2"),
        ("mid_block.attentions.0", "middle_block.1"),
    ] {
        add(d.into(), o.into(), false);
    }
    add("mid_block.resnets.0".into(), "middle_block.0".into(), true);
    add("mid_block.resnets.1".into(), "middle_block.2".into(), true);
    for i in 0..levels {
        for j in 0..l {
            let block = (l + 1) * i + j + 1;
            add(format!("down_blocks.{i}.resnets.{j}"), format!("input_blocks.{block}.0"), true);
            add(format!("down_blocks.{i}.attentions.{j}"), format!("input_blocks.{block}.1"), false);
        }
        if i + 1 < levels {
            add(
                format!("down_blocks.{i}.downsamplers.0.conv"),
                format!("input_blocks.{}.0.op", (l + 1) * (i + 1)),
                false,
            );
        }
        for j in 0..=l {
            let block = (l + 1) * i + j;
            add(format!("up_blocks.{i}.resnets.{j}"), format!("output_blocks.{block}.0"), true);
            add(format!("up_blocks.{i}.attentions.{j}"), format!("output_blocks.{block}.1"), false);
        }
        if i + 1 < levels {
            // The upsampler follows the resnet and, where there is one, the attention.
            let slot = if config.up_block_types[i] == "CrossAttnUpBlock2D" { 2 } else { 1 };
            add(
                format!("up_blocks.{i}.upsamplers.0.conv"),
                format!("output_blocks.{}.{slot}.conv", (l + 1) * i + l),
                false,
            );
        }
    }
    Ok(names)
}

/// Distinct values of the number following `prefix` in any key.
fn indices(shapes: &HashMap<&str, &[usize]>, prefix: &str) -> BTreeSet<usize> {
    shapes.keys().filter_map(|k| k.strip_prefix(prefix)?.split('.').next()?.parse().ok()).collect()
}

/// A UNet config from the shapes of an original-layout UNet's tensors (names without the
/// `model.diffusion_model.` prefix). Head counts, norm groups and the size-embedding width are
/// not visible in shapes and take SDXL's values (64 channels per head, 32 groups, 256), as sgm's
/// and ComfyUI's loaders assume.
pub fn infer_unet_config(shapes: &HashMap<&str, &[usize]>) -> std::result::Result<UNetConfig, String> {
    let get = |k: &str| shapes.get(k).copied().ok_or_else(|| format!("no tensor `model.diffusion_model.{k}`"));
    // Dimension `i` of a tensor, which a tensor of too low a rank lacks.
    let dim = |k: &str, i: usize| {
        let s = get(k)?;
        s.get(i).copied().ok_or_else(|| {
            format!("tensor `model.diffusion_model.{k}` has shape {s:?}; a weight there has more dimensions")
        })
    };
    let in_channels = dim("input_blocks.0.0.weight", 1)?;
    let out_channels = dim("out.2.weight", 0)?;
    let inputs = indices(shapes, "input_blocks.");
    let first_down =
        inputs.iter().copied().find(|&n| shapes.contains_key(format!("input_blocks.{n}.0.op.weight").as_str()));
    let l = match first_down {
        Some(n) => n - 1,
        None => *inputs.iter().max().unwrap_or(&0),
    };
    if l == 0 {
        return Err("no resnet blocks under `input_blocks.*`".into());
    }
    let levels =
        1 + inputs.iter().filter(|n| shapes.contains_key(format!("input_blocks.{n}.0.op.weight").as_str())).count();
    let depth_at = |prefix: String| indices(shapes, &format!("{prefix}.1.transformer_blocks.")).len();
    let has_attention = |prefix: String| shapes.contains_key(format!("{prefix}.1.proj_in.weight").as_str());
    let mut channels = Vec::new();
    let mut down_types = Vec::new();
    let mut depths = Vec::new();
    let mut heads = Vec::new();
    for i in 0..levels {
        let block = format!("input_blocks.{}", (l + 1) * i + 1);
        let c = dim(&format!("{block}.0.out_layers.3.weight"), 0)?;
        channels.push(c);
        let attn = has_attention(block.clone());
        down_types.push(if attn { "CrossAttnDownBlock2D" } else { "DownBlock2D" });
        depths.push(if attn { depth_at(block) } else { 1 });
        heads.push((c / HEAD_CHANNELS).max(1));
    }
    let up_types: Vec<&str> =
        (0..levels)
            .map(|i| {
                if has_attention(format!("output_blocks.{}", (l + 1) * i)) {
                    "CrossAttnUpBlock2D"
                } else {
                    "UpBlock2D"
                }
            })
            .collect();
    let up_depths: Vec<usize> =
        (0..levels).map(|i| depth_at(format!("output_blocks.{}", (l + 1) * i)).max(1)).collect();
    let mid_depth = depth_at("middle_block".into());
    if mid_depth != depths[levels - 1] {
        return Err(format!(
            "middle block has {mid_depth} transformer blocks but the last level {}; diffusers' UNet cannot hold that",
            depths[levels - 1]
        ));
    }
    let cross_key = shapes
        .keys()
        .find(|k| k.ends_with("attn2.to_k.weight"))
        .ok_or("no cross-attention (`…attn2.to_k.weight`) tensors")?;
    let cross = dim(cross_key, 1)?;
    let linear = shapes.iter().find(|(k, _)| k.ends_with(".1.proj_in.weight")).is_some_and(|(_, s)| s.len() == 2);
    let time_embed = dim("time_embed.0.weight", 0)?;
    let mut config = serde_json::json!({
        "in_channels": in_channels,
        "out_channels": out_channels,
        "block_out_channels": channels,
        "down_block_types": down_types,
        "up_block_types": up_types,
        "layers_per_block": l,
        "transformer_layers_per_block": depths,
        "reverse_transformer_layers_per_block": up_depths,
        "attention_head_dim": heads,
        "cross_attention_dim": cross,
        "use_linear_projection": linear,
        "time_embedding_dim": time_embed,
    });
    if shapes.contains_key("label_emb.0.0.weight") {
        config["addition_embed_type"] = "text_time".into();
        config["addition_time_embed_dim"] = TIME_ID_DIM.into();
        config["projection_class_embeddings_input_dim"] = dim("label_emb.0.0.weight", 1)?.into();
    }
    let config: UNetConfig = serde_json::from_value(config).map_err(|e| e.to_string())?;
    config.validate().map_err(|e: Error| e.to_string())?;
    Ok(config)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sdxl() -> UNetConfig {
        serde_json::from_value(serde_json::json!({
            "in_channels": 4, "out_channels": 4, "block_out_channels": [320, 640, 1280],
            "down_block_types": ["DownBlock2D", "CrossAttnDownBlock2D", "CrossAttnDownBlock2D"],
            "up_block_types": ["CrossAttnUpBlock2D", "CrossAttnUpBlock2D", "UpBlock2D"],
            "layers_per_block": 2, "transformer_layers_per_block": [1, 2, 10],
            "attention_head_dim": [5, 10, 20], "cross_attention_dim": 2048
        }))
        .unwrap()
    }

    #[test]
    fn sdxl_examples_from_the_reference() {
        // reference/sdxl.md §2.2's worked examples and the upsampler slot exception.
        let n = unet_names(&sdxl()).unwrap();
        let cases = [
            (
                "down_blocks.2.attentions.1.transformer_blocks.9.attn2.to_k.weight",
                "input_blocks.8.1.transformer_blocks.9.attn2.to_k.weight",
            ),
            ("up_blocks.2.resnets.2.conv_shortcut.weight", "output_blocks.8.0.skip_connection.weight"),
            ("up_blocks.0.upsamplers.0.conv.bias", "output_blocks.2.2.conv.bias"),
            ("up_blocks.1.upsamplers.0.conv.weight", "output_blocks.5.2.conv.weight"),
            ("down_blocks.1.downsamplers.0.conv.weight", "input_blocks.6.0.op.weight"),
            ("mid_block.resnets.1.time_emb_proj.weight", "middle_block.2.emb_layers.1.weight"),
            ("add_embedding.linear_2.bias", "label_emb.0.2.bias"),
        ];
        for (d, o) in cases {
            assert_eq!(n.rename(d).map(|s| s.name).as_deref(), Some(o), "{d}");
        }
        assert_eq!(n.rename("up_blocks.0.resnets.0.nonsense.weight"), None);
    }
}
