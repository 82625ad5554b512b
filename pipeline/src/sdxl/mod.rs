//! An SDXL model on the device: both tokenizers and text encoders, the UNet, the VAE and the
//! scheduler config, from a diffusers folder or an original single file; and everything it runs:
//! prompt encoding (plain and weighted), the batched denoiser with its ControlNet and IP-Adapter
//! guides, img2img's init latents, text-to-image, and the paper's workflow loaded once.

pub(crate) mod controlnet_guide;
pub(crate) mod denoiser;
mod img2img;
mod ip_adapter_guide;
pub(crate) mod prompt_encoding;
mod prompt_weights;
pub(crate) mod regions;
mod text_to_image;
mod vae_plan;
mod workflow_models;

pub use controlnet_guide::{check_control_shape, ControlGuide, ControlNetUse};
pub use denoiser::{BatchOutput, Denoiser, IpAdapterUse, ItemInputs};
pub use img2img::InitLatents;
pub use ip_adapter_guide::ImageGuide;
pub use prompt_encoding::Conditioning;
pub use regions::Regions;
pub use text_to_image::{Denoised, Generated, Guides, Timings};
pub use vae_plan::VaePlan;
pub use workflow_models::{StyleModels, WorkflowModels};

use crate::error::{Error, Result};
use crate::schedulers::SchedulerConfig;
use crate::settings::models::flagged;
use crate::tokenizer::ClipTokenizer;
use std::path::Path;
use vkdiff_formats::Error as FileError;
use vkdiff_lora::{Component, LoraFile, LoraMerger, Summary, Targets};
use vkdiff_networks::{
    read_unet_config, swapped_unet_checkpoint, swapped_unet_config, unet_checkpoint, AutoencoderKl, Checkpoint,
    ClipTextModel, TextEncoderSlot, UNet, UNetConfig, VaeConfig, SDXL_BIGG_CONFIG, SDXL_CLIP_L_CONFIG, SDXL_VAE_CONFIG,
};
use vkdiff_runtime::{Context, Dtype};

/// Components taken from elsewhere than the model folder or file: `--vae` (a folder, or a file
/// in either layout) and `--unet` (a folder, or a file of the model's UNet architecture).
#[derive(Clone, Copy, Debug, Default)]
pub struct Swaps<'a> {
    pub vae: Option<&'a Path>,
    pub unet: Option<&'a Path>,
}

pub struct Sdxl {
    pub(crate) ctx: Context,
    pub(crate) dtype: Dtype,
    pub(crate) tokenizers: [ClipTokenizer; 2],
    /// None once released ([`Sdxl::release_text_encoders`]).
    text_encoders: Option<[ClipTextModel; 2]>,
    /// The encoders' widths, kept past their release: features per token of each, and the
    /// pooled projection's.
    pub(crate) text_widths: ([usize; 2], usize),
    pub(crate) unet_config: UNetConfig,
    pub(crate) unet: UNet,
    pub(crate) vae: AutoencoderKl,
    pub(crate) scheduler: SchedulerConfig,
    /// model_index.json's `force_zeros_for_empty_prompt`: no negative prompt means zero
    /// negative conditioning rather than the encoding of "".
    pub(crate) force_zeros_for_empty_prompt: bool,
    /// The LoRAs merged into the weights, and the originals to restore.
    loras: LoraMerger,
    /// How the VAE decodes (whole or in tiles), as [`Sdxl::plan_vae`] chose.
    vae_plan: Option<VaePlan>,
}

impl Sdxl {
    /// Loads every component, reporting each by name to `progress` before it loads.
    pub fn load(ctx: &Context, path: &Path, dtype: Dtype, progress: &mut dyn FnMut(&str)) -> Result<Sdxl> {
        Sdxl::load_with(ctx, path, Swaps::default(), dtype, progress)
    }

    /// [`Sdxl::load`] with the components `swaps` names taken from there instead of the model.
    pub fn load_with(
        ctx: &Context,
        path: &Path,
        swaps: Swaps,
        dtype: Dtype,
        progress: &mut dyn FnMut(&str),
    ) -> Result<Sdxl> {
        if !path.exists() {
            return Err(Error::Config(format!("{}: no such model folder or file", path.display())));
        }
        let folder = path.is_dir().then_some(path);
        progress("tokenizers");
        let tokenizer =
            |sub: &str, pad: &str| match folder.map(|d| d.join(sub)).filter(|d| d.join("vocab.json").is_file()) {
                Some(dir) => ClipTokenizer::from_dir(&dir),
                None => ClipTokenizer::builtin(pad),
            };
        let tokenizers = [tokenizer("tokenizer", "<|endoftext|>")?, tokenizer("tokenizer_2", "!")?];
        progress("text encoders");
        let text_encoders = [
            ClipTextModel::load_sdxl(ctx, path, TextEncoderSlot::ClipL, dtype)?,
            ClipTextModel::load_sdxl(ctx, path, TextEncoderSlot::BigG, dtype)?,
        ];
        progress("UNet");
        let (unet_config, ckpt) = match swaps.unet {
            Some(unet) => {
                let base = read_unet_config(path)?;
                flagged("unet", unet, swapped_unet_checkpoint(ctx, unet, &base, dtype))?
            }
            None => unet_checkpoint(ctx, path, dtype)?,
        };
        let unet = match swaps.unet {
            Some(file) => flagged("unet", file, UNet::load(&unet_config, &ckpt))?,
            None => UNet::load(&unet_config, &ckpt)?,
        };
        progress("VAE");
        let vae = match swaps.vae {
            Some(file) => flagged("vae", file, AutoencoderKl::load_sdxl(ctx, file, dtype))?,
            None => AutoencoderKl::load_sdxl(ctx, path, dtype)?,
        };
        let scheduler = SchedulerConfig::of_model(path)?;
        let force_zeros_for_empty_prompt = match folder.map(|d| d.join("model_index.json")).filter(|p| p.is_file()) {
            Some(p) => read_force_zeros(&p)?,
            None => true,
        };
        let model = Sdxl::assemble(ctx, dtype, tokenizers, text_encoders, (unet_config, unet), vae, scheduler);
        let model = Sdxl { force_zeros_for_empty_prompt, ..model };
        model.check_widths()?;
        Ok(model)
    }

    /// A model of these parts, no LoRA merged and no VAE plan yet; no negative prompt encodes
    /// as zeros, as SDXL base's model_index.json says.
    fn assemble(
        ctx: &Context,
        dtype: Dtype,
        tokenizers: [ClipTokenizer; 2],
        text_encoders: [ClipTextModel; 2],
        (unet_config, unet): (UNetConfig, UNet),
        vae: AutoencoderKl,
        scheduler: SchedulerConfig,
    ) -> Sdxl {
        Sdxl {
            ctx: ctx.clone(),
            dtype,
            tokenizers,
            text_widths: text_widths(&text_encoders),
            text_encoders: Some(text_encoders),
            unet_config,
            unet,
            vae,
            scheduler,
            force_zeros_for_empty_prompt: true,
            loras: LoraMerger::new(),
            vae_plan: None,
        }
    }

    /// SDXL base's architecture with random weights (benchmarks: real sizes, no download), the
    /// ones `write_random_single_file` writes.
    pub fn random_sdxl_base(ctx: &Context, dtype: Dtype) -> Result<Sdxl> {
        use vkdiff_networks::RANDOM_SEEDS as SEEDS;
        let text_encoders = [
            ClipTextModel::load(
                ctx,
                builtin(SDXL_CLIP_L_CONFIG),
                &Checkpoint::random(ctx, dtype, SEEDS.clip_l),
                false,
            )?,
            ClipTextModel::load(ctx, builtin(SDXL_BIGG_CONFIG), &Checkpoint::random(ctx, dtype, SEEDS.big_g), true)?,
        ];
        let unet_config = UNetConfig::sdxl_base();
        let unet = UNet::load(&unet_config, &Checkpoint::random(ctx, dtype, SEEDS.unet))?;
        let vae_config: VaeConfig = builtin(SDXL_VAE_CONFIG);
        let vae_dtype = AutoencoderKl::run_dtype(&vae_config, dtype);
        let vae = AutoencoderKl::load(ctx, vae_config, &Checkpoint::random(ctx, vae_dtype, SEEDS.vae))?;
        let tokenizers = [ClipTokenizer::builtin("<|endoftext|>")?, ClipTokenizer::builtin("!")?];
        let scheduler = SchedulerConfig::sdxl_base();
        Ok(Sdxl::assemble(ctx, dtype, tokenizers, text_encoders, (unet_config, unet), vae, scheduler))
    }

    /// The text encoders' widths must be what the UNet was trained on.
    fn check_widths(&self) -> Result<()> {
        let [a, b] = self.text_encoders()?.each_ref().map(|e| e.config());
        let context = a.hidden_size + b.hidden_size;
        if context != self.unet_config.cross_attention_dim {
            return Err(Error::Config(format!(
                "text encoders give {context}-wide context ({} + {}), the UNet attends to {}",
                a.hidden_size, b.hidden_size, self.unet_config.cross_attention_dim
            )));
        }
        let pooled = b.projection_dim.unwrap_or(0);
        let time_ids = 6 * self.unet_config.addition_time_embed_dim.unwrap_or(0);
        if self.unet_config.projection_class_embeddings_input_dim != Some(pooled + time_ids) {
            return Err(Error::Config(format!(
                "the UNet's added conditioning takes {:?} features; pooled text ({pooled}) + time ids ({time_ids}) \
                    give {}",
                self.unet_config.projection_class_embeddings_input_dim,
                pooled + time_ids
            )));
        }
        Ok(())
    }

    /// Pixels per latent along each side.
    /// The precision the VAE runs in: f32 where its config forces upcasting.
    pub fn vae_dtype(&self) -> Dtype {
        self.vae.dtype()
    }

    pub fn vae_scale(&self) -> usize {
        self.vae.config().downscale()
    }

    /// Latent sides must be multiples of this (each UNet level halves them).
    pub fn latent_multiple(&self) -> usize {
        1 << (self.unet_config.block_out_channels.len() - 1)
    }

    /// Image sides must be multiples of this: the VAE's scale times the UNet's latent multiple.
    pub fn pixel_multiple(&self) -> usize {
        self.vae_scale() * self.latent_multiple()
    }

    /// Pixels per latent along a side: the VAE's downscale, read from its config alone.
    pub fn probe_vae_scale(path: &Path, swaps: Swaps) -> Result<usize> {
        Ok(probe_vae_config(path, swaps)?.downscale())
    }

    /// [`Sdxl::pixel_multiple`] of the model at `path`, read from its configs or tensor shapes
    /// without loading any weight (to check sizes before the long load).
    pub fn probe_pixel_multiple(path: &Path, swaps: Swaps) -> Result<usize> {
        if !path.exists() {
            return Err(Error::Config(format!("{}: no such model folder or file", path.display())));
        }
        let unet = read_unet_config(path)?;
        let unet = match swaps.unet {
            Some(file) => flagged("unet", file, swapped_unet_config(file, &unet))?,
            None => unet,
        };
        let vae = probe_vae_config(path, swaps)?;
        if unet.block_out_channels.is_empty() || vae.block_out_channels.is_empty() {
            return Err(Error::Config(format!("{}: a UNet or VAE config without block_out_channels", path.display())));
        }
        Ok(vae.downscale() << (unet.block_out_channels.len() - 1))
    }

    pub fn dtype(&self) -> Dtype {
        self.dtype
    }

    pub fn unet_config(&self) -> &UNetConfig {
        &self.unet_config
    }

    pub fn unet(&self) -> &UNet {
        &self.unet
    }

    /// Merges `loras` (file, strength) into the UNet and text encoders on the device, replacing
    /// whatever set was merged before; an empty list restores the original weights exactly.
    pub fn set_loras(&mut self, loras: &[(&LoraFile, f32)]) -> Result<Option<Summary>> {
        if loras.is_empty() {
            self.loras.restore()?;
            return Ok(None);
        }
        let [first, second] = self
            .text_encoders
            .as_ref()
            .ok_or_else(|| Error::Config("LoRAs cannot be merged once the text encoders are released".into()))?;
        let targets = Targets::sdxl(&self.unet, first, second);
        Ok(Some(self.loras.apply(&targets, loras)?))
    }
}

impl Sdxl {
    /// Both text encoders, unless released.
    pub(crate) fn text_encoders(&self) -> Result<&[ClipTextModel; 2]> {
        self.text_encoders.as_ref().ok_or_else(|| {
            Error::Config("the text encoders were released once the prompts were encoded; nothing more can be".into())
        })
    }

    /// Frees the text encoders (1.6 GiB of host memory for SDXL in f16) once every prompt a
    /// run needs is encoded, and returns the bytes freed. Prompts cannot be encoded after it,
    /// nor LoRAs merged anew.
    pub fn release_text_encoders(&mut self) -> u64 {
        let held = |ctx: &Context| ctx.live_bytes() + ctx.host_bytes();
        let before = held(&self.ctx);
        self.text_encoders = None;
        self.loras.forget(Component::TextEncoder1);
        self.loras.forget(Component::TextEncoder2);
        before.saturating_sub(held(&self.ctx))
    }
}

/// What [`Sdxl::text_widths`] keeps of the encoders.
fn text_widths([first, second]: &[ClipTextModel; 2]) -> ([usize; 2], usize) {
    let hidden = [first.config().hidden_size, second.config().hidden_size];
    (hidden, second.config().projection_dim.unwrap_or(0))
}

fn builtin<T: serde::de::DeserializeOwned>(text: &str) -> T {
    serde_json::from_str(text).expect("built-in config parses")
}

fn read_force_zeros(path: &Path) -> Result<bool> {
    let text = std::fs::read_to_string(path).map_err(|e| FileError::Io { path: path.to_path_buf(), source: e })?;
    let json: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| FileError::Format { path: path.to_path_buf(), why: format!("not JSON: {e}") })?;
    Ok(json.get("force_zeros_for_empty_prompt").and_then(|v| v.as_bool()).unwrap_or(true))
}

/// The config of the VAE a run uses: `--vae`'s, else the model's.
fn probe_vae_config(path: &Path, swaps: Swaps) -> Result<vkdiff_networks::VaeConfig> {
    match swaps.vae {
        Some(file) => flagged("vae", file, AutoencoderKl::sdxl_config(file)),
        None => Ok(AutoencoderKl::sdxl_config(path)?),
    }
}
