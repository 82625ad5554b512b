//! SDXL's text encoders in the original single-file layout: where each lives, the OpenCLIP
//! names of the bigG tower (reference/sdxl.md §2.4), and the config read back from shapes.

use crate::clip::text_config::ClipTextConfig;
use crate::error::{Error, Result};
use crate::weights::{Inner, OriginalNames, StoredAs};
use vkdiff_formats::SafeTensors;

/// Which of SDXL's two text encoders.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TextEncoderSlot {
    /// CLIP ViT-L/14 (`text_encoder/`, `conditioner.embedders.0.transformer.`).
    ClipL,
    /// OpenCLIP ViT-bigG/14 with projection (`text_encoder_2/`, `conditioner.embedders.1.model.`).
    BigG,
}

impl TextEncoderSlot {
    pub fn folder(self) -> &'static str {
        match self {
            TextEncoderSlot::ClipL => "text_encoder",
            TextEncoderSlot::BigG => "text_encoder_2",
        }
    }

    pub fn single_file_prefix(self) -> &'static str {
        match self {
            TextEncoderSlot::ClipL => "conditioner.embedders.0.transformer.",
            TextEncoderSlot::BigG => "conditioner.embedders.1.model.",
        }
    }
}

/// Inside one OpenCLIP residual block: transformers name → OpenCLIP name.
const RESBLOCK: [(&str, &str); 3] = [("layer_norm1", "ln_1"), ("layer_norm2", "ln_2"), ("self_attn", "attn")];
const MLP: [(&str, &str); 2] = [("fc1", "c_fc"), ("fc2", "c_proj")];

/// transformers names of the bigG text tower → OpenCLIP's: q/k/v are row blocks of the fused
/// `in_proj`, and `text_projection` is stored as the matrix applied as `x @ P` (the transpose).
pub fn open_clip_names(layers: usize) -> OriginalNames {
    let mut n = OriginalNames::default();
    let plain = |s: &str| StoredAs::plain(s.into());
    n.tensor("text_model.embeddings.token_embedding.weight", plain("token_embedding.weight"));
    n.tensor("text_model.embeddings.position_embedding.weight", plain("positional_embedding"));
    n.tensor("text_projection.weight", StoredAs { name: "text_projection".into(), rows: None, transposed: true });
    n.module("text_model.final_layer_norm", "ln_final", Inner::Same);
    for i in 0..layers {
        let (hf, oc) = (format!("text_model.encoder.layers.{i}"), format!("transformer.resblocks.{i}"));
        for (part, proj) in ["q_proj", "k_proj", "v_proj"].iter().enumerate() {
            for kind in ["weight", "bias"] {
                let fused =
                    StoredAs { name: format!("{oc}.attn.in_proj_{kind}"), rows: Some((part, 3)), transposed: false };
                n.tensor(&format!("{hf}.self_attn.{proj}.{kind}"), fused);
            }
        }
        // The MLP rule first: the block rule would otherwise take `mlp.*` and reject it.
        n.module(&format!("{hf}.mlp"), &format!("{oc}.mlp"), Inner::Strict(&MLP));
        n.module(&hf, &oc, Inner::Strict(&RESBLOCK));
    }
    n
}

/// A text encoder's config from its single-file tensor shapes. Heads of 64 channels and the
/// activations (quick GELU for CLIP-L, GELU for bigG) are the SDXL conventions shapes cannot show.
pub fn infer_text_config(file: &SafeTensors, slot: TextEncoderSlot) -> Result<ClipTextConfig> {
    let prefix = slot.single_file_prefix();
    let big = slot == TextEncoderSlot::BigG;
    let shape = |name: &str| {
        file.entries.get(&format!("{prefix}{name}")).map(|e| e.shape.clone()).ok_or_else(|| {
            Error::Checkpoint(format!(
                "{}: no tensor `{prefix}{name}`; not an SDXL single-file checkpoint with both text encoders",
                file.path.display()
            ))
        })
    };
    let dim = |name: &str, i: usize| {
        let s = shape(name)?;
        s.get(i).copied().ok_or_else(|| {
            Error::Checkpoint(format!(
                "{}: tensor `{prefix}{name}` has shape {s:?}; a weight there has more dimensions",
                file.path.display()
            ))
        })
    };
    let (tokens, positions, layer, fc1, layers_prefix) = if big {
        (
            "token_embedding.weight",
            "positional_embedding",
            "transformer.resblocks.",
            "mlp.c_fc.weight",
            "transformer.resblocks.",
        )
    } else {
        (
            "text_model.embeddings.token_embedding.weight",
            "text_model.embeddings.position_embedding.weight",
            "text_model.encoder.layers.",
            "mlp.fc1.weight",
            "text_model.encoder.layers.",
        )
    };
    let [vocab, hidden] = shape(tokens)?[..] else {
        return Err(Error::Checkpoint(format!("{}: `{prefix}{tokens}` is not a matrix", file.path.display())));
    };
    let layers = file
        .entries
        .keys()
        .filter_map(|k| k.strip_prefix(prefix)?.strip_prefix(layers_prefix)?.split('.').next()?.parse::<usize>().ok())
        .max()
        .map_or(0, |m| m + 1);
    let config = ClipTextConfig {
        vocab_size: vocab,
        hidden_size: hidden,
        intermediate_size: dim(&format!("{layer}0.{fc1}"), 0)?,
        num_hidden_layers: layers,
        num_attention_heads: (hidden / 64).max(1),
        max_position_embeddings: dim(positions, 0)?,
        hidden_act: if big { "gelu" } else { "quick_gelu" }.into(),
        layer_norm_eps: 1e-5,
        projection_dim: if big { Some(dim("text_projection", 1)?) } else { None },
        eos_token_id: 2,
    };
    Ok(config)
}
