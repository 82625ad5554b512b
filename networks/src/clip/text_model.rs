//! transformers' `CLIPTextModel` and `CLIPTextModelWithProjection`: SDXL's two text encoders
//! (CLIP ViT-L and OpenCLIP ViT-bigG), returning what SDXL consumes: the penultimate hidden
//! states and, with a projection, the pooled EOS feature projected.

use crate::clip::names::{infer_text_config, open_clip_names, TextEncoderSlot};
use crate::clip::text_config::ClipTextConfig;
use crate::error::{Error, Result};
use crate::layers::biased_attention::BiasedSelfAttention;
use crate::layers::nn::{Graph, LayerNorm, Linear};
use crate::weights::read_config;
use crate::weights::Parameters;
use crate::weights::{component_folder, Checkpoint, Weights};
use std::path::Path;
use vkdiff_formats::SafeTensors;
use vkdiff_runtime::ops::{self, UnaryOp};
use vkdiff_runtime::{Context, Dtype, Tensor};

/// What SDXL takes from a text encoder for a batch of prompts.
pub struct TextEncoding {
    /// hidden_states[-2]: [B, tokens, hidden], row-major, f32.
    pub penultimate: Vec<f32>,
    /// The final-LayerNorm feature at each prompt's EOS, projected: [B, projection_dim].
    pub pooled: Option<Vec<f32>>,
}

pub(crate) struct EncoderLayer {
    layer_norm1: LayerNorm,
    self_attn: BiasedSelfAttention,
    layer_norm2: LayerNorm,
    fc1: Linear,
    fc2: Linear,
}

impl EncoderLayer {
    /// One `CLIPEncoderLayer` of `hidden` channels over `heads` heads and an MLP of `intermediate`;
    /// shared by the text and the vision towers.
    pub(crate) fn load(
        w: &Weights,
        hidden: usize,
        intermediate: usize,
        heads: usize,
        eps: f32,
    ) -> Result<EncoderLayer> {
        let names = ["self_attn.q_proj", "self_attn.k_proj", "self_attn.v_proj", "self_attn.out_proj"];
        Ok(EncoderLayer {
            layer_norm1: LayerNorm::load(w, "layer_norm1", hidden, eps)?,
            self_attn: BiasedSelfAttention::load(w, names, hidden, heads)?,
            layer_norm2: LayerNorm::load(w, "layer_norm2", hidden, eps)?,
            fc1: Linear::load(w, "mlp.fc1", hidden, intermediate, true)?,
            fc2: Linear::load(w, "mlp.fc2", intermediate, hidden, true)?,
        })
    }

    /// Pre-LN block on the residual stream `x` [B, N, C], in place; `causal` for the text tower.
    pub(crate) fn forward(&self, g: &mut Graph, x: &Tensor, act: UnaryOp, causal: bool) -> Result<()> {
        let h = self.layer_norm1.forward(g, x)?;
        self.self_attn.forward_residual(g, &h, x, causal)?;
        let h = self.layer_norm2.forward(g, x)?;
        let f = self.fc1.forward(g, &h)?;
        ops::unary(&mut g.rec, act, &f, &f, 1.0)?;
        self.fc2.forward_into(g, &f, x, true, 1.0)
    }
}

/// A CLIP text transformer on the device; token and position embeddings stay on the host, where
/// looking up 77 rows is cheaper than a kernel.
pub struct ClipTextModel {
    config: ClipTextConfig,
    ctx: Context,
    dtype: Dtype,
    token_embedding: Vec<f32>,
    position_embedding: Vec<f32>,
    /// Only the layers up to the penultimate output, plus the last one when pooling.
    layers: Vec<EncoderLayer>,
    final_layer_norm: Option<LayerNorm>,
    /// [projection_dim, hidden] on the host: applied to B rows only.
    projection: Option<Vec<f32>>,
    parameters: Parameters,
}

impl ClipTextModel {
    /// Text encoder `slot` of an SDXL model: a diffusers folder (`text_encoder/` or
    /// `text_encoder_2/`) or an original single file (`conditioner.embedders.{0,1}.*`).
    pub fn load_sdxl(ctx: &Context, path: &Path, slot: TextEncoderSlot, dtype: Dtype) -> Result<ClipTextModel> {
        let pooled = slot == TextEncoderSlot::BigG;
        if path.is_dir() {
            let folder = component_folder(path, slot.folder())?;
            let config = Self::sdxl_config(path, slot)?;
            let ckpt = Checkpoint::diffusers(ctx, &folder, "model", dtype)?.level_optional("text_model.");
            return Self::load(ctx, config, &ckpt, pooled);
        }
        let file = SafeTensors::open(path)?;
        let config = infer_text_config(&file, slot)?;
        let names = (slot == TextEncoderSlot::BigG).then(|| open_clip_names(config.num_hidden_layers));
        let ckpt = Checkpoint::single_file_part(ctx, file, slot.single_file_prefix(), names, dtype);
        Self::load(ctx, config, &ckpt, pooled)
    }

    /// The config [`ClipTextModel::load_sdxl`] builds from `path`, without its weights.
    pub fn sdxl_config(path: &Path, slot: TextEncoderSlot) -> Result<ClipTextConfig> {
        if path.is_dir() {
            read_config(&component_folder(path, slot.folder())?.join("config.json"), "a CLIP text")
        } else {
            infer_text_config(&SafeTensors::open(path)?, slot)
        }
    }

    /// Builds the encoder from its config; with `pooled`, also the final norm and projection.
    pub fn load(ctx: &Context, config: ClipTextConfig, ckpt: &Checkpoint, pooled: bool) -> Result<ClipTextModel> {
        config.validate()?;
        // Run once per prompt: the device reads the weights from host memory (see
        // `Weights::in_host_memory`), leaving its own memory to the denoiser.
        let w = ckpt.root().in_host_memory().sub("text_model");
        let h = config.hidden_size;
        let emb = w.sub("embeddings");
        let token_embedding = emb.host("token_embedding.weight", &[config.vocab_size, h])?;
        let position_embedding = emb.host("position_embedding.weight", &[config.max_position_embeddings, h])?;
        let used = if pooled { config.num_hidden_layers } else { config.num_hidden_layers - 1 };
        let (mlp, heads, eps) = (config.intermediate_size, config.num_attention_heads, config.layer_norm_eps);
        let layers = (0..used)
            .map(|i| EncoderLayer::load(&w.sub("encoder.layers").sub(&i.to_string()), h, mlp, heads, eps))
            .collect::<Result<_>>()?;
        let (final_layer_norm, projection) = if pooled {
            let proj = config.projection_dim.ok_or_else(|| {
                Error::Config("text encoder 2 has no `projection_dim`; SDXL needs CLIPTextModelWithProjection".into())
            })?;
            (
                Some(LayerNorm::load(&w, "final_layer_norm", h, config.layer_norm_eps)?),
                Some(ckpt.root().host("text_projection.weight", &[proj, h])?),
            )
        } else {
            (None, None)
        };
        let mut parameters = ckpt.parameters();
        if !pooled {
            parameters.mark_not_run(format!("text_model.encoder.layers.{used}."));
            parameters.mark_not_run("text_model.final_layer_norm.".into());
        }
        Ok(ClipTextModel {
            config,
            ctx: ctx.clone(),
            dtype: ckpt.dtype(),
            token_embedding,
            position_embedding,
            layers,
            final_layer_norm,
            projection,
            parameters,
        })
    }

    pub fn config(&self) -> &ClipTextConfig {
        &self.config
    }

    /// The weights on the device by transformers name (`text_model.encoder.layers.0.mlp.fc1.weight`).
    pub fn parameters(&self) -> &Parameters {
        &self.parameters
    }

    /// Encodes a batch of token sequences, all of one length.
    pub fn encode(&self, ids: &[Vec<u32>]) -> Result<TextEncoding> {
        let (b, n, h) = (ids.len(), ids.first().map_or(0, Vec::len), self.config.hidden_size);
        if b == 0 || n == 0 || n > self.config.max_position_embeddings || ids.iter().any(|s| s.len() != n) {
            return Err(Error::Config(format!(
                "text encoder: {b} prompts of {n} tokens; the model takes 1..={} tokens each",
                self.config.max_position_embeddings
            )));
        }
        let mut embedded = Vec::with_capacity(b * n * h);
        for seq in ids {
            for (pos, &id) in seq.iter().enumerate() {
                let id = id as usize;
                if id >= self.config.vocab_size {
                    return Err(Error::Config(format!(
                        "token id {id} is outside the text encoder's {} vocabulary",
                        self.config.vocab_size
                    )));
                }
                let tok = &self.token_embedding[id * h..][..h];
                let p = &self.position_embedding[pos * h..][..h];
                embedded.extend(tok.iter().zip(p).map(|(a, b)| a + b));
            }
        }
        let mut g = Graph::new(&self.ctx, self.dtype)?;
        let x = self.ctx.upload(&[b, n, h], self.dtype, &embedded)?;
        let act = self.config.activation()?;
        let penultimate_at = self.config.num_hidden_layers - 1;
        let penultimate = g.alloc(&[b, n, h])?;
        for (i, layer) in self.layers.iter().enumerate() {
            if i == penultimate_at {
                ops::unary(&mut g.rec, UnaryOp::Scale, &x, &penultimate, 1.0)?;
            }
            layer.forward(&mut g, &x, act, true)?;
        }
        if self.layers.len() == penultimate_at {
            ops::unary(&mut g.rec, UnaryOp::Scale, &x, &penultimate, 1.0)?;
        }
        let normed = self.final_layer_norm.as_ref().map(|ln| ln.forward(&mut g, &x)).transpose()?;
        g.rec.finish()?.run()?;
        let pooled = match (normed, &self.projection) {
            (Some(normed), Some(proj)) => Some(self.pool(ids, &normed.download()?, proj)),
            _ => None,
        };
        Ok(TextEncoding { penultimate: penultimate.download()?, pooled })
    }

    /// The projected final-norm feature at each sequence's EOS token: transformers takes the
    /// largest id (legacy eos_token_id 2) or else the first EOS.
    fn pool(&self, ids: &[Vec<u32>], normed: &[f32], proj: &[f32]) -> Vec<f32> {
        let (n, h) = (ids[0].len(), self.config.hidden_size);
        let mut out = Vec::new();
        for (bi, seq) in ids.iter().enumerate() {
            let eos = if self.config.eos_token_id == 2 {
                // First position of the maximum, as torch.argmax returns.
                seq.iter().enumerate().fold(0, |best, (i, &id)| if id > seq[best] { i } else { best })
            } else {
                seq.iter().position(|&id| id == self.config.eos_token_id).unwrap_or(0)
            };
            let row = &normed[(bi * n + eos) * h..][..h];
            out.extend(
                proj.chunks_exact(h).map(|p| p.iter().zip(row).map(|(&a, &b)| a as f64 * b as f64).sum::<f64>() as f32),
            );
        }
        out
    }
}
