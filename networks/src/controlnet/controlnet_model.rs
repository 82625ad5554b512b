//! diffusers `ControlNetModel`: a trained copy of the UNet's down path and mid block, steered by
//! an encoded conditioning image, whose zero-convolved skips become residuals for the UNet.

use crate::controlnet::config::{cldm_names, ControlNetConfig};
use crate::controlnet::union::UnionExtras;
use crate::error::{Error, Result};
use crate::layers::nn::{Conv2d, Graph, Recorded};
use crate::unet::config::UNetConfig;
use crate::unet::down_path::{DownConditioning, DownOutput, DownPath};
use crate::unet::unet_2d_blocks::{Conditioning, MidBlock};
use crate::unet::unet_2d_condition::ControlResiduals;
use crate::weights::{component_folder, Checkpoint, Weights};
use std::path::Path;
use vkdiff_formats::SafeTensors;
use vkdiff_runtime::ops::{self, UnaryOp};
use vkdiff_runtime::{Context, Dtype, Tensor};

/// `ControlNetConditioningEmbedding`: 3×3 convs with SiLU, each stage after the first halving the
/// image, down to the latent grid, then a last conv to the UNet's first width.
struct ConditioningEmbedding {
    convs: Vec<Conv2d>,
}

impl ConditioningEmbedding {
    fn load(w: &Weights, config: &ControlNetConfig) -> Result<ConditioningEmbedding> {
        let c = &config.embedding_channels;
        let mut convs = vec![Conv2d::load(w, "conv_in", config.conditioning_channels, c[0], 3, 1, 1)?];
        for i in 0..c.len() - 1 {
            convs.push(Conv2d::load(w, &format!("blocks.{}", 2 * i), c[i], c[i], 3, 1, 1)?);
            convs.push(Conv2d::load(w, &format!("blocks.{}", 2 * i + 1), c[i], c[i + 1], 3, 2, 1)?);
        }
        convs.push(Conv2d::load(w, "conv_out", c[c.len() - 1], config.encoder.block_out_channels[0], 3, 1, 1)?);
        Ok(ConditioningEmbedding { convs })
    }

    fn forward_into(&self, g: &mut Graph, image: &Tensor, out: &Tensor) -> Result<()> {
        let (last, hidden) = self.convs.split_last().expect("at least conv_in and conv_out");
        let mut h = image.clone();
        for conv in hidden {
            h = conv.forward(g, &h)?;
            ops::unary(&mut g.rec, UnaryOp::Silu, &h, &h, 1.0)?;
        }
        last.forward_into(g, &h, out, false)
    }
}

/// One evaluation's inputs: the UNet's own inputs (same tensors) and the encoded image.
pub struct ControlNetInputs<'a> {
    /// [B, h, w, in_channels], the scaled latents exactly as the UNet gets them.
    pub sample: &'a Tensor,
    pub timesteps: &'a Tensor,
    pub encoder_hidden_states: &'a Tensor,
    pub added: Option<(&'a Tensor, &'a Tensor)>,
    /// [B, h, w, C0] from [`ControlNetModel::encode_condition`].
    pub hint: &'a Tensor,
    /// Multiplies every residual (`controlnet_conditioning_scale`).
    pub scale: f32,
    /// A ControlNet-Union's active control types (diffusers' multi-hot `control_type`), whose
    /// embedding joins the time embedding; empty for a plain ControlNet, never for a Union.
    pub control_types: &'a [usize],
    /// Another ControlNet's residuals, onto which this one's are added after it writes its own:
    /// several ControlNets summed as diffusers' `MultiControlNetModel` sums them.
    pub add_to: Option<&'a ControlResiduals>,
}

/// A recorded ControlNet evaluation writing `residuals`, which a recorded UNet pass reads; as
/// with [`crate::UNetPass`], [`ControlNetPass::project_conditioning`] after each change of the
/// prompt's encoder hidden states.
pub struct ControlNetPass {
    recorded: Recorded,
    pub residuals: ControlResiduals,
}

impl ControlNetPass {
    pub fn project_conditioning(&self) -> Result<()> {
        self.recorded.project_conditioning()
    }

    pub fn run(&self) -> Result<()> {
        Ok(self.recorded.evaluation.run()?)
    }
}

pub struct ControlNetModel {
    config: ControlNetConfig,
    pub(super) dtype: Dtype,
    embedding: ConditioningEmbedding,
    down: DownPath,
    mid: MidBlock,
    /// `controlnet_down_blocks`: one 1×1 conv per skip.
    zero_convs: Vec<Conv2d>,
    zero_mid: Conv2d,
    /// A ControlNet-Union's extras.
    pub(super) union: Option<UnionExtras>,
}

impl ControlNetModel {
    /// A ControlNet for the UNet configured by `unet`: a diffusers folder (`config.json` +
    /// `diffusion_pytorch_model[.fp16].safetensors`) or one safetensors file in the diffusers or
    /// the original (cldm, optionally `control_model.`-prefixed) layout.
    pub fn load(ctx: &Context, path: &Path, unet: &UNetConfig, dtype: Dtype) -> Result<ControlNetModel> {
        if path.is_dir() {
            let folder = component_folder(path, "controlnet")?;
            let config = ControlNetConfig::from_file(&folder.join("config.json"))?;
            return Self::build(config, &Checkpoint::diffusers(ctx, &folder, "diffusion_pytorch_model", dtype)?, unet);
        }
        let file = SafeTensors::open(path)?;
        if file.entries.keys().any(|k| k.starts_with("lora_controlnet")) {
            return Err(Error::Checkpoint(format!(
                "{}: a Control-LoRA, not a ControlNet; vkdiff does not read Control-LoRAs",
                path.display()
            )));
        }
        let hint_in = |k: &String| k.strip_suffix("input_hint_block.0.weight").map(str::to_string);
        let ckpt = if file.entries.contains_key("controlnet_cond_embedding.conv_in.weight") {
            Checkpoint::single_file_part(ctx, file, "", None, dtype)
        } else if let Some(prefix) = file.entries.keys().find_map(hint_in) {
            let stages = (0..)
                .take_while(|k| file.entries.contains_key(&format!("{prefix}input_hint_block.{}.weight", 2 * k)))
                .count()
                / 2;
            if stages == 0 {
                return Err(Error::Checkpoint(format!(
                    "{}: `input_hint_block` has too few convolutions",
                    path.display()
                )));
            }
            Checkpoint::single_file_part(ctx, file, &prefix, Some(cldm_names(unet, stages)?), dtype)
        } else {
            return Err(Error::Checkpoint(format!(
                "{}: not a ControlNet (no `controlnet_cond_embedding.*` or `input_hint_block.*` tensors)",
                path.display()
            )));
        };
        Self::build(ControlNetConfig::infer(unet, &ckpt)?, &ckpt, unet)
    }

    /// Builds the network `config` describes, with every weight from `ckpt`, checking that it
    /// fits the UNet configured by `unet`; a ControlNet-Union when `ckpt` has a `task_embedding`
    /// (random weights: when the config names `num_control_type`).
    pub fn build(config: ControlNetConfig, ckpt: &Checkpoint, unet: &UNetConfig) -> Result<ControlNetModel> {
        check_fits(&config.encoder, unet)?;
        let w = ckpt.root();
        let mut crosses = Vec::new();
        let down = DownPath::load(&w, &config.encoder, &mut crosses)?;
        let mid = down.load_mid(&w, &config.encoder, &mut crosses)?;
        let zero = |name: String, c: usize| Conv2d::load(&w, &name, c, c, 1, 1, 0);
        let zero_convs = skip_channels(&config.encoder)
            .iter()
            .enumerate()
            .map(|(k, &c)| zero(format!("controlnet_down_blocks.{k}"), c))
            .collect::<Result<_>>()?;
        let last = *config.encoder.block_out_channels.last().expect("validated");
        Ok(ControlNetModel {
            union: UnionExtras::load(&w, ckpt, &config)?,
            embedding: ConditioningEmbedding::load(&w.sub("controlnet_cond_embedding"), &config)?,
            zero_mid: zero("controlnet_mid_block".into(), last)?,
            dtype: ckpt.dtype(),
            config,
            down,
            mid,
            zero_convs,
        })
    }

    pub fn config(&self) -> &ControlNetConfig {
        &self.config
    }

    /// Encodes the conditioning image(s) [B, H, W, 3] (RGB in [0, 1], run precision; H and W a
    /// multiple of the encoder's downscale) once: the hint every evaluation adds after conv_in.
    pub fn encode_condition(&self, image: &Tensor) -> Result<Tensor> {
        let out = image.context().zeros(&self.hint_shape(image.shape())?, self.dtype)?;
        self.encode_condition_into(image, &out)?;
        Ok(out)
    }

    /// [`ControlNetModel::encode_condition`] into an existing hint tensor, so that a recorded
    /// pass reading `out` sees the new image.
    pub fn encode_condition_into(&self, image: &Tensor, out: &Tensor) -> Result<()> {
        self.check_hint_tensor(image.shape(), out)?;
        let ctx = image.context();
        let mut g = Graph::new(&ctx, self.dtype)?;
        let image = if self.config.bgr { self.reversed_channels(image)? } else { image.clone() };
        self.embedding.forward_into(&mut g, &image, out)?;
        g.rec.finish()?.run()?;
        Ok(())
    }

    /// The hint's shape for a conditioning image of shape `image`, which `out` must have.
    pub(super) fn check_hint_tensor(&self, image: &[usize], out: &Tensor) -> Result<[usize; 4]> {
        let want = self.hint_shape(image)?;
        if out.shape() != want || out.dtype() != self.dtype {
            return Err(Error::Config(format!(
                "ControlNet hint tensor is {:?}, the image {image:?} needs {want:?}",
                out.shape()
            )));
        }
        Ok(want)
    }

    /// The hint's shape for a conditioning image of shape `s`, which must be [B, H, W, channels]
    /// with sides a multiple of the encoder's downscale.
    fn hint_shape(&self, s: &[usize]) -> Result<[usize; 4]> {
        let down = self.config.downscale();
        if s.len() != 4
            || s[3] != self.config.conditioning_channels
            || !s[1].is_multiple_of(down)
            || !s[2].is_multiple_of(down)
        {
            return Err(Error::Config(format!(
                "ControlNet conditioning image must be [B, H, W, {}] with sides a multiple of {down}, got {s:?}",
                self.config.conditioning_channels
            )));
        }
        Ok([s[0], s[1] / down, s[2] / down, self.config.encoder.block_out_channels[0]])
    }

    fn reversed_channels(&self, image: &Tensor) -> Result<Tensor> {
        let rgb = image.download()?;
        let bgr: Vec<f32> = rgb.chunks_exact(3).flat_map(|p| [p[2], p[1], p[0]]).collect();
        Ok(image.context().upload(image.shape(), image.dtype(), &bgr)?)
    }

    /// Records one evaluation on `inputs`' shapes.
    pub fn record(&self, inputs: &ControlNetInputs) -> Result<ControlNetPass> {
        let s = inputs.sample.shape();
        let c0 = self.config.encoder.block_out_channels[0];
        if inputs.hint.shape() != [s[0], s[1], s[2], c0] {
            return Err(Error::Config(format!(
                "ControlNet hint {:?} does not match the latents {s:?}",
                inputs.hint.shape()
            )));
        }
        let ctx = inputs.sample.context();
        let control = self.control_embedding(&ctx, inputs.control_types, s[0])?;
        let mut g = Graph::new(&ctx, self.dtype)?;
        let cond = DownConditioning {
            context: inputs.encoder_hidden_states,
            ip: &[],
            hint: Some(inputs.hint),
            emb_add: control.as_ref(),
        };
        let DownOutput { h, skips, emb_silu } =
            self.down.forward(&mut g, inputs.sample, inputs.timesteps, inputs.added, &cond)?;
        let mid_cond = Conditioning { emb_silu: &emb_silu, context: inputs.encoder_hidden_states, ip: &[] };
        let h = self.mid.forward(&mut g, &h, &mid_cond)?;
        let mut down = Vec::with_capacity(skips.len());
        for (skip, conv) in skips.iter().zip(&self.zero_convs) {
            down.push(self.zero_conv(&mut g, conv, skip, inputs.scale)?);
        }
        let mid = self.zero_conv(&mut g, &self.zero_mid, &h, inputs.scale)?;
        if let Some(sum) = inputs.add_to {
            if sum.down.len() != down.len() {
                return Err(Error::Config(format!(
                    "ControlNets of {} and {} residuals cannot be summed",
                    sum.down.len(),
                    down.len()
                )));
            }
            for (total, own) in sum.down.iter().zip(&down).chain([(&sum.mid, &mid)]) {
                ops::add(&mut g.rec, total, own, total)?;
            }
        }
        Ok(ControlNetPass { recorded: g.finish()?, residuals: ControlResiduals { down, mid } })
    }

    /// scale · conv(x) into a tensor of its own, which outlives the recording's arena.
    fn zero_conv(&self, g: &mut Graph, conv: &Conv2d, x: &Tensor, scale: f32) -> Result<Tensor> {
        let out = x.context().zeros(x.shape(), self.dtype)?;
        conv.forward_into(g, x, &out, false)?;
        if scale != 1.0 {
            ops::unary(&mut g.rec, UnaryOp::Scale, &out, &out, scale)?;
        }
        Ok(out)
    }
}

/// Channels of the down path's skips: conv_in's, then each resnet's and downsampler's.
fn skip_channels(config: &UNetConfig) -> Vec<usize> {
    let c = &config.block_out_channels;
    let mut out = vec![c[0]];
    for (i, &ch) in c.iter().enumerate() {
        out.extend(std::iter::repeat_n(ch, config.layers_per_block + usize::from(i + 1 < c.len())));
    }
    out
}

/// A ControlNet must copy the UNet it steers: the same levels, widths and conditioning.
fn check_fits(control: &UNetConfig, unet: &UNetConfig) -> Result<()> {
    let pairs = [
        ("in_channels", control.in_channels, unet.in_channels),
        ("layers_per_block", control.layers_per_block, unet.layers_per_block),
        ("cross_attention_dim", control.cross_attention_dim, unet.cross_attention_dim),
        ("time embedding width", control.time_embed_dim(), unet.time_embed_dim()),
    ];
    for (what, c, u) in pairs {
        if c != u {
            return Err(Error::Config(format!(
                "the ControlNet has {what} {c} but the UNet {u}: it was made for another model"
            )));
        }
    }
    if control.block_out_channels != unet.block_out_channels {
        return Err(Error::Config(format!(
            "the ControlNet's block_out_channels {:?} differ from the UNet's {:?}: it was made for another model",
            control.block_out_channels, unet.block_out_channels
        )));
    }
    if control.projection_class_embeddings_input_dim != unet.projection_class_embeddings_input_dim {
        return Err(Error::Config(
            "the ControlNet's added (text/time) conditioning differs from the UNet's: it was made for another model"
                .into(),
        ));
    }
    Ok(())
}
