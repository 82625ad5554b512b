//! transformers' `CLIPVisionModelWithProjection`: IP-Adapter's image encoder (OpenCLIP ViT-H/14 or
//! ViT-bigG/14 vision towers), returning what the adapters consume: the projected class-token
//! feature (`image_embeds`) and the penultimate hidden states (`hidden_states[-2]`).

use crate::clip::text_model::EncoderLayer;
use crate::error::{Error, Result};
use crate::layers::nn::{Graph, LayerNorm, Linear};
use crate::weights::{component_folder, Checkpoint};
use serde::Deserialize;
use std::path::Path;
use vkdiff_formats::Error as FileError;
use vkdiff_runtime::ops::{self, Matmul, UnaryOp};
use vkdiff_runtime::{Context, Dtype, Placement, Tensor};

/// The keys of a transformers `CLIPVisionConfig` vkdiff reads, with transformers' defaults.
#[derive(Clone, Debug, Deserialize)]
#[serde(default)]
pub struct ClipVisionConfig {
    pub hidden_size: usize,
    pub intermediate_size: usize,
    pub num_hidden_layers: usize,
    pub num_attention_heads: usize,
    pub num_channels: usize,
    pub image_size: usize,
    pub patch_size: usize,
    pub projection_dim: usize,
    pub hidden_act: String,
    pub layer_norm_eps: f32,
}

impl Default for ClipVisionConfig {
    fn default() -> Self {
        ClipVisionConfig {
            hidden_size: 768,
            intermediate_size: 3072,
            num_hidden_layers: 12,
            num_attention_heads: 12,
            num_channels: 3,
            image_size: 224,
            patch_size: 32,
            projection_dim: 512,
            hidden_act: "quick_gelu".into(),
            layer_norm_eps: 1e-5,
        }
    }
}

impl ClipVisionConfig {
    /// A `config.json` holding a `CLIPVisionConfig`, or a full `CLIPConfig` whose `vision_config`
    /// is used (as transformers does when loading a vision model from it).
    pub fn from_file(path: &Path) -> Result<ClipVisionConfig> {
        let bad = |why: String| Error::from(FileError::Format { path: path.to_path_buf(), why });
        let text = std::fs::read_to_string(path).map_err(|e| FileError::Io { path: path.to_path_buf(), source: e })?;
        let json: serde_json::Value = serde_json::from_str(&text).map_err(|e| bad(format!("not JSON: {e}")))?;
        let mut vision = json.get("vision_config").cloned().unwrap_or_else(|| json.clone());
        // A nested vision_config without its own projection_dim takes the CLIPConfig's.
        if let (Some(v), Some(p)) = (vision.as_object_mut(), json.get("projection_dim")) {
            v.entry("projection_dim").or_insert_with(|| p.clone());
        }
        let config: ClipVisionConfig =
            serde_json::from_value(vision).map_err(|e| bad(format!("not a CLIP vision config: {e}")))?;
        config.validate()?;
        Ok(config)
    }

    fn activation(&self) -> Result<UnaryOp> {
        match self.hidden_act.as_str() {
            "quick_gelu" => Ok(UnaryOp::QuickGelu),
            "gelu" => Ok(UnaryOp::Gelu),
            "gelu_new" | "gelu_pytorch_tanh" => Ok(UnaryOp::GeluTanh),
            other => Err(Error::Config(format!(
                "image encoder `hidden_act` {other:?} is not supported (quick_gelu, gelu, gelu_pytorch_tanh)"
            ))),
        }
    }

    fn validate(&self) -> Result<()> {
        self.activation()?;
        let heads = self.num_attention_heads;
        if heads == 0 || !self.hidden_size.is_multiple_of(heads) {
            return Err(Error::Config(format!(
                "image encoder: {} channels do not split into {heads} heads",
                self.hidden_size
            )));
        }
        if self.patch_size == 0 || self.image_size < self.patch_size || self.num_channels == 0 {
            return Err(Error::Config(format!(
                "image encoder: image size {} with patch size {} has no patches",
                self.image_size, self.patch_size
            )));
        }
        if self.num_hidden_layers == 0 {
            return Err(Error::Config("image encoder: `num_hidden_layers` is 0".into()));
        }
        Ok(())
    }

    /// Patches along each side of the image.
    fn grid(&self) -> usize {
        self.image_size / self.patch_size
    }

    /// Sequence length: the class token and one token per patch.
    pub fn tokens(&self) -> usize {
        self.grid() * self.grid() + 1
    }
}

/// An encoder output an IP-Adapter projects.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageFeature {
    /// `image_embeds`: visual_projection(post_layernorm(last_hidden[:, 0])), [B, projection_dim].
    ImageEmbeds,
    /// `hidden_states[-2]`: the second-to-last layer's output, no post-LayerNorm, [B, tokens, hidden].
    Penultimate,
}

/// What [`ClipVisionModelWithProjection::encode`] computed, row-major f32.
pub struct ImageEncoding {
    pub batch: usize,
    /// [B, projection_dim], when asked for.
    pub image_embeds: Option<Vec<f32>>,
    /// [B, tokens, hidden], when asked for.
    pub penultimate: Option<Vec<f32>>,
    penultimate_shape: [usize; 3],
    embeds_shape: [usize; 2],
}

impl ImageEncoding {
    /// One output and its shape, if it was computed.
    pub fn get(&self, feature: ImageFeature) -> Option<(&[f32], Vec<usize>)> {
        match feature {
            ImageFeature::ImageEmbeds => self.image_embeds.as_deref().map(|v| (v, self.embeds_shape.to_vec())),
            ImageFeature::Penultimate => self.penultimate.as_deref().map(|v| (v, self.penultimate_shape.to_vec())),
        }
    }
}

/// A CLIP vision transformer with its projection, on the device.
pub struct ClipVisionModelWithProjection {
    config: ClipVisionConfig,
    ctx: Context,
    dtype: Dtype,
    /// The patch convolution as a linear map of flattened (channel, y, x) patches: [hidden, C·p·p].
    patch_embedding: Linear,
    /// Position embeddings with the class embedding added to row 0: [tokens, hidden].
    positions: Tensor,
    pre_layrnorm: LayerNorm,
    layers: Vec<EncoderLayer>,
    post_layernorm: LayerNorm,
    /// [projection_dim, hidden], no bias.
    visual_projection: Linear,
}

impl ClipVisionModelWithProjection {
    /// An `image_encoder/` folder (or its parent) of the diffusers/transformers layout:
    /// `config.json` and `model[.fp16].safetensors`.
    pub fn load_folder(ctx: &Context, path: &Path, dtype: Dtype) -> Result<ClipVisionModelWithProjection> {
        let folder = component_folder(path, "image_encoder")?;
        let config = ClipVisionConfig::from_file(&folder.join("config.json"))?;
        let ckpt = Checkpoint::diffusers(ctx, &folder, "model", dtype)?;
        Self::load(ctx, config, &ckpt)
    }

    /// Builds the encoder from its config with weights named as transformers names them.
    pub fn load(ctx: &Context, config: ClipVisionConfig, ckpt: &Checkpoint) -> Result<ClipVisionModelWithProjection> {
        config.validate()?;
        let (h, eps) = (config.hidden_size, config.layer_norm_eps);
        // Run once per style image: weights in host memory, as the text encoders' are.
        let root = ckpt.root().in_host_memory();
        let w = root.sub("vision_model");
        let emb = w.sub("embeddings");
        let (c, p) = (config.num_channels, config.patch_size);
        // [hidden, C, p, p] flattened row-major is already [hidden, C·p·p] in the patch order used below.
        let patch = emb.host("patch_embedding.weight", &[h, c, p, p])?;
        let patch_embedding =
            Linear { weight: ctx.upload_to(Placement::Host, &[h, c * p * p], ckpt.dtype(), &patch)?, bias: None };
        let mut positions = emb.host("position_embedding.weight", &[config.tokens(), h])?;
        let class = emb.host("class_embedding", &[h])?;
        positions[..h].iter_mut().zip(&class).for_each(|(p, c)| *p += c);
        let layers = (0..config.num_hidden_layers)
            .map(|i| {
                EncoderLayer::load(
                    &w.sub("encoder.layers").sub(&i.to_string()),
                    h,
                    config.intermediate_size,
                    config.num_attention_heads,
                    eps,
                )
            })
            .collect::<Result<_>>()?;
        Ok(ClipVisionModelWithProjection {
            positions: ctx.upload(&[config.tokens(), h], ckpt.dtype(), &positions)?,
            pre_layrnorm: LayerNorm::load(&w, "pre_layrnorm", h, eps)?,
            post_layernorm: LayerNorm::load(&w, "post_layernorm", h, eps)?,
            visual_projection: Linear::load(&root, "visual_projection", h, config.projection_dim, false)?,
            layers,
            patch_embedding,
            ctx: ctx.clone(),
            dtype: ckpt.dtype(),
            config,
        })
    }

    pub fn config(&self) -> &ClipVisionConfig {
        &self.config
    }

    /// Encodes `pixel_values` (NCHW f32 [B, C, S, S], already CLIP-normalised), computing only
    /// the `wanted` outputs and running only the layers they need.
    pub fn encode(&self, pixel_values: &[f32], batch: usize, wanted: &[ImageFeature]) -> Result<ImageEncoding> {
        let c = &self.config;
        let (s, h, n) = (c.image_size, c.hidden_size, c.tokens());
        if batch == 0 || pixel_values.len() != batch * c.num_channels * s * s {
            return Err(Error::Config(format!(
                "image encoder takes pixel_values [B, {}, {s}, {s}]; got {} values for B = {batch}",
                c.num_channels,
                pixel_values.len()
            )));
        }
        let want_embeds = wanted.contains(&ImageFeature::ImageEmbeds);
        let want_penultimate = wanted.contains(&ImageFeature::Penultimate);
        let layers = c.num_hidden_layers;
        // hidden_states[-2] is the input of the last layer, which then need not run.
        let run = if want_embeds { layers } else { layers - 1 };

        let mut g = Graph::new(&self.ctx, self.dtype)?;
        let patches = self.ctx.upload(
            &[batch, n, c.num_channels * c.patch_size * c.patch_size],
            self.dtype,
            &self.im2col(pixel_values, batch),
        )?;
        let x = self.patch_embedding.forward(&mut g, &patches)?;
        ops::add(&mut g.rec, &x, &self.positions, &x)?;
        let x = self.pre_layrnorm.forward(&mut g, &x)?;
        let act = c.activation()?;
        let penultimate = if want_penultimate { Some(g.alloc(&[batch, n, h])?) } else { None };
        for (i, layer) in self.layers[..run].iter().enumerate() {
            if let (Some(p), true) = (&penultimate, i == layers - 1) {
                ops::unary(&mut g.rec, UnaryOp::Scale, &x, p, 1.0)?;
            }
            layer.forward(&mut g, &x, act, false)?;
        }
        if let (Some(p), true) = (&penultimate, run == layers - 1) {
            ops::unary(&mut g.rec, UnaryOp::Scale, &x, p, 1.0)?;
        }
        let embeds = if want_embeds {
            let normed = self.post_layernorm.forward(&mut g, &x)?;
            // Project only each image's class token: rows n·h apart.
            let out = g.alloc(&[batch, c.projection_dim])?;
            let mut spec = Matmul::dense(batch, c.projection_dim, h, true);
            (spec.lda, spec.a_batch) = (n * h, batch * n * h);
            ops::matmul(&mut g.rec, &normed, &self.visual_projection.weight, None, &out, &spec)?;
            Some(out)
        } else {
            None
        };
        g.rec.finish()?.run()?;
        Ok(ImageEncoding {
            batch,
            image_embeds: embeds.map(|t| t.download()).transpose()?,
            penultimate: penultimate.map(|t| t.download()).transpose()?,
            penultimate_shape: [batch, n, h],
            embeds_shape: [batch, c.projection_dim],
        })
    }

    /// Each image's patches as rows of (channel, y, x) values, after a zero row standing in for
    /// the class token (whose embedding comes with the positions): [B, tokens, C·p·p].
    fn im2col(&self, pixels: &[f32], batch: usize) -> Vec<f32> {
        let c = &self.config;
        let (s, p, ch, grid) = (c.image_size, c.patch_size, c.num_channels, c.grid());
        let k = ch * p * p;
        let mut out = vec![0.0; batch * c.tokens() * k];
        for b in 0..batch {
            for gy in 0..grid {
                for gx in 0..grid {
                    let row = &mut out[(b * c.tokens() + 1 + gy * grid + gx) * k..][..k];
                    for ci in 0..ch {
                        for y in 0..p {
                            let src = ((b * ch + ci) * s + gy * p + y) * s + gx * p;
                            row[(ci * p + y) * p..][..p].copy_from_slice(&pixels[src..src + p]);
                        }
                    }
                }
            }
        }
        out
    }
}
