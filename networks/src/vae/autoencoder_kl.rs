//! diffusers `AutoencoderKL`: the VAE's encoder (image → latent mean and log-variance) and
//! decoder (latent → image), built from its config. Activations past the binding limit (a
//! 1024² decode) run in exact bands inside the ops, so no tiling seams appear.

use crate::error::{Error, Result};
use crate::layers::biased_attention::BiasedSelfAttention;
use crate::layers::nn::{Conv2d, Graph, GroupNorm};
use crate::layers::resnet::{Downsample2D, NormSpec, ResnetBlock2D, Upsample2D};
use crate::vae::config::VaeConfig;
use crate::vae::names::{infer_vae_config, vae_names, SingleFileVae};
use crate::weights::read_config;
use crate::weights::{component_folder, Checkpoint, Weights};
use std::path::Path;
use vkdiff_formats::SafeTensors;
use vkdiff_runtime::{Context, Dtype, Tensor};

/// The mid block: resnet, single-head attention over all positions, resnet.
struct MidBlock {
    resnet_0: ResnetBlock2D,
    attention: Option<(GroupNorm, BiasedSelfAttention)>,
    resnet_1: ResnetBlock2D,
}

impl MidBlock {
    fn load(w: &Weights, channels: usize, norm: NormSpec, attention: bool) -> Result<MidBlock> {
        let attention = if attention {
            let a = w.sub("attentions.0");
            let norm = GroupNorm::load(&a, "group_norm", channels, norm.groups, norm.eps)?;
            Some((norm, BiasedSelfAttention::load(&a, ["to_q", "to_k", "to_v", "to_out.0"], channels, 1)?))
        } else {
            None
        };
        Ok(MidBlock {
            resnet_0: ResnetBlock2D::load(&w.sub("resnets.0"), channels, channels, None, norm)?,
            attention,
            resnet_1: ResnetBlock2D::load(&w.sub("resnets.1"), channels, channels, None, norm)?,
        })
    }

    fn forward(&self, g: &mut Graph, x: &Tensor) -> Result<Tensor> {
        let h = self.resnet_0.forward(g, x, None)?;
        if let Some((norm, attn)) = &self.attention {
            let [b, hh, ww, c] = [h.shape()[0], h.shape()[1], h.shape()[2], h.shape()[3]];
            let normed = norm.forward(g, &h, false)?.reshape(&[b, hh * ww, c])?;
            attn.forward_residual(g, &normed, &h.reshape(&[b, hh * ww, c])?, false)?;
        }
        self.resnet_1.forward(g, &h, None)
    }
}

/// One level: resnets, then a resampler (down in the encoder, up in the decoder) except last.
struct Level {
    resnets: Vec<ResnetBlock2D>,
    down: Option<Downsample2D>,
    up: Option<Upsample2D>,
}

impl Level {
    fn forward(&self, g: &mut Graph, x: &Tensor) -> Result<Tensor> {
        let mut h = self.resnets[0].forward(g, x, None)?;
        for r in &self.resnets[1..] {
            h = r.forward(g, &h, None)?;
        }
        match (&self.down, &self.up) {
            (Some(d), _) => d.forward(g, &h),
            (_, Some(u)) => u.forward(g, &h),
            _ => Ok(h),
        }
    }
}

/// Encoder or decoder: conv_in, levels, mid block, norm + SiLU, conv_out, and the 1×1
/// (post-)quant conv on the latent side.
struct Coder {
    conv_in: Conv2d,
    levels: Vec<Level>,
    mid: MidBlock,
    norm_out: GroupNorm,
    conv_out: Conv2d,
    quant: Option<Conv2d>,
}

pub struct AutoencoderKl {
    config: VaeConfig,
    ctx: Context,
    dtype: Dtype,
    encoder: Coder,
    decoder: Coder,
}

impl AutoencoderKl {
    /// The VAE of an SDXL model, or a VAE alone (`--vae`): a diffusers folder (`vae/` or the
    /// folder itself), a whole single-file checkpoint (`first_stage_model.*`), or a VAE file in
    /// the original or diffusers names. A VAE file's config is the diffusers config.json beside
    /// it where there is one (the fp16-fix VAE's lets it run in f16), else read from its shapes
    /// with SDXL's scaling and forced f32. It runs in f32 when the config forces upcasting,
    /// else in `dtype`.
    pub fn load_sdxl(ctx: &Context, path: &Path, dtype: Dtype) -> Result<AutoencoderKl> {
        if path.is_dir() {
            // The config first: it decides the precision, and so which weight variant to open.
            let config = Self::sdxl_config(path)?;
            let ckpt = Checkpoint::diffusers(
                ctx,
                &component_folder(path, "vae")?,
                "diffusion_pytorch_model",
                Self::run_dtype(&config, dtype),
            )?;
            return Self::load(ctx, config, &ckpt);
        }
        let file = SafeTensors::open(path)?;
        let layout = SingleFileVae::of(&file);
        let config = single_file_config(path, &file, layout)?;
        let names = (!layout.diffusers_names).then(|| vae_names(&config));
        let ckpt = Checkpoint::single_file_part(ctx, file, layout.prefix, names, Self::run_dtype(&config, dtype));
        Self::load(ctx, config, &ckpt)
    }

    /// The config of the VAE [`AutoencoderKl::load_sdxl`] would load from `path`, without its weights.
    pub fn sdxl_config(path: &Path) -> Result<VaeConfig> {
        if path.is_dir() {
            read_config(&component_folder(path, "vae")?.join("config.json"), "an AutoencoderKL")
        } else {
            let file = SafeTensors::open(path)?;
            single_file_config(path, &file, SingleFileVae::of(&file))
        }
    }

    /// The precision a VAE with `config` runs in when the run asks for `dtype`.
    pub fn run_dtype(config: &VaeConfig, dtype: Dtype) -> Dtype {
        if config.force_upcast {
            Dtype::F32
        } else {
            dtype
        }
    }

    pub fn load(ctx: &Context, config: VaeConfig, ckpt: &Checkpoint) -> Result<AutoencoderKl> {
        config.validate()?;
        let w = ckpt.root();
        let norm = NormSpec { groups: config.norm_num_groups, eps: 1e-6 };
        let ch = &config.block_out_channels;
        let (l, last) = (config.layers_per_block, *ch.last().unwrap());
        let lat = config.latent_channels;
        let quant = |name: &str, c: usize, on: bool| {
            if on {
                Conv2d::load(&w, name, c, c, 1, 1, 0).map(Some)
            } else {
                Ok(None)
            }
        };

        let e = w.sub("encoder");
        let mut levels = Vec::new();
        let mut prev = ch[0];
        for (i, &c) in ch.iter().enumerate() {
            let b = e.sub(&format!("down_blocks.{i}"));
            let resnets = (0..l)
                .map(|j| {
                    ResnetBlock2D::load(&b.sub(&format!("resnets.{j}")), if j == 0 { prev } else { c }, c, None, norm)
                })
                .collect::<Result<_>>()?;
            let down = if i + 1 < ch.len() { Some(Downsample2D::load(&b.sub("downsamplers.0"), c, 0)?) } else { None };
            levels.push(Level { resnets, down, up: None });
            prev = c;
        }
        let encoder = Coder {
            conv_in: Conv2d::load(&e, "conv_in", config.in_channels, ch[0], 3, 1, 1)?,
            levels,
            mid: MidBlock::load(&e.sub("mid_block"), last, norm, config.mid_block_add_attention)?,
            norm_out: GroupNorm::load(&e, "conv_norm_out", last, norm.groups, norm.eps)?,
            conv_out: Conv2d::load(&e, "conv_out", last, 2 * lat, 3, 1, 1)?,
            quant: quant("quant_conv", 2 * lat, config.use_quant_conv)?,
        };

        let d = w.sub("decoder");
        let mut levels = Vec::new();
        let mut prev = last;
        for (i, &c) in ch.iter().rev().enumerate() {
            let b = d.sub(&format!("up_blocks.{i}"));
            let resnets = (0..=l)
                .map(|j| {
                    ResnetBlock2D::load(&b.sub(&format!("resnets.{j}")), if j == 0 { prev } else { c }, c, None, norm)
                })
                .collect::<Result<_>>()?;
            let up = if i + 1 < ch.len() { Some(Upsample2D::load(&b.sub("upsamplers.0"), c)?) } else { None };
            levels.push(Level { resnets, down: None, up });
            prev = c;
        }
        let decoder = Coder {
            conv_in: Conv2d::load(&d, "conv_in", lat, last, 3, 1, 1)?,
            levels,
            mid: MidBlock::load(&d.sub("mid_block"), last, norm, config.mid_block_add_attention)?,
            norm_out: GroupNorm::load(&d, "conv_norm_out", ch[0], norm.groups, norm.eps)?,
            conv_out: Conv2d::load(&d, "conv_out", ch[0], config.out_channels, 3, 1, 1)?,
            quant: quant("post_quant_conv", lat, config.use_post_quant_conv)?,
        };
        Ok(AutoencoderKl { config, ctx: ctx.clone(), dtype: ckpt.dtype(), encoder, decoder })
    }

    pub fn config(&self) -> &VaeConfig {
        &self.config
    }

    /// The precision the VAE runs in.
    pub fn dtype(&self) -> Dtype {
        self.dtype
    }

    /// Decoder output [B, H·s, W·s, out_channels] (NHWC, ≈[-1, 1]) of latents [B, h, w, C]
    /// (NHWC, already divided by the scaling factor, as diffusers passes them to `decode`).
    pub fn decode(&self, latents: &[f32], shape: [usize; 4]) -> Result<(Vec<f32>, [usize; 4])> {
        let [b, h, w, c] = shape;
        if c != self.config.latent_channels {
            return Err(Error::Config(format!("VAE takes {} latent channels, got {c}", self.config.latent_channels)));
        }
        let mut g = Graph::new(&self.ctx, self.dtype)?;
        let x = self.ctx.upload(&shape, self.dtype, latents)?;
        let x = match &self.decoder.quant {
            Some(q) => q.forward(&mut g, &x)?,
            None => x,
        };
        let mut h_ = self.decoder.conv_in.forward(&mut g, &x)?;
        h_ = self.decoder.mid.forward(&mut g, &h_)?;
        for level in &self.decoder.levels {
            h_ = level.forward(&mut g, &h_)?;
        }
        let h_ = self.decoder.norm_out.forward(&mut g, &h_, true)?;
        let out = self.decoder.conv_out.forward(&mut g, &h_)?;
        g.rec.finish()?.run()?;
        let s = self.config.downscale();
        Ok((out.download()?, [b, h * s, w * s, self.config.out_channels]))
    }

    /// The latent distribution's (mean, logvar) [B, h, w, C] each (NHWC) of images
    /// [B, H, W, in_channels] in [-1, 1] (NHWC). Sides must be multiples of the downscale.
    pub fn encode(&self, images: &[f32], shape: [usize; 4]) -> Result<(Vec<f32>, Vec<f32>)> {
        let [_, h, w, c] = shape;
        let s = self.config.downscale();
        if c != self.config.in_channels || !h.is_multiple_of(s) || !w.is_multiple_of(s) {
            return Err(Error::Config(format!(
                "VAE encodes {}-channel images with sides divisible by {s}, got {w}×{h}×{c}",
                self.config.in_channels
            )));
        }
        let mut g = Graph::new(&self.ctx, self.dtype)?;
        let x = self.ctx.upload(&shape, self.dtype, images)?;
        let mut h_ = self.encoder.conv_in.forward(&mut g, &x)?;
        for level in &self.encoder.levels {
            h_ = level.forward(&mut g, &h_)?;
        }
        h_ = self.encoder.mid.forward(&mut g, &h_)?;
        let h_ = self.encoder.norm_out.forward(&mut g, &h_, true)?;
        let mut moments = self.encoder.conv_out.forward(&mut g, &h_)?;
        if let Some(q) = &self.encoder.quant {
            moments = q.forward(&mut g, &moments)?;
        }
        g.rec.finish()?.run()?;
        let lat = self.config.latent_channels;
        let m = moments.download()?;
        let (mut mean, mut logvar) = (Vec::with_capacity(m.len() / 2), Vec::with_capacity(m.len() / 2));
        for px in m.chunks_exact(2 * lat) {
            mean.extend_from_slice(&px[..lat]);
            // diffusers clamps the log-variance to [-30, 20].
            logvar.extend(px[lat..].iter().map(|v| v.clamp(-30.0, 20.0)));
        }
        Ok((mean, logvar))
    }
}

/// A single file's VAE config: for a VAE file alone, a diffusers `AutoencoderKL` config.json
/// beside it (as its repository keeps one); else from the shapes.
fn single_file_config(path: &Path, file: &SafeTensors, layout: SingleFileVae) -> Result<VaeConfig> {
    let beside = path.with_file_name("config.json");
    if layout.prefix.is_empty() && beside.is_file() {
        let text = std::fs::read_to_string(&beside).unwrap_or_default();
        let class = serde_json::from_str::<serde_json::Value>(&text)
            .ok()
            .and_then(|v| v["_class_name"].as_str().map(String::from));
        if class.as_deref() == Some("AutoencoderKL") {
            return read_config(&beside, "an AutoencoderKL");
        }
    }
    infer_vae_config(file, layout)
}
