//! Text-to-image as diffusers' `StableDiffusionXLPipeline` runs it: both prompts encoded, the
//! initial noise and any ancestral noise drawn from one torch-compatible generator, classifier-free
//! guidance on a batch of [negative, positive], the scheduler's steps, then the VAE. One image is a
//! batch of one through [`Denoiser`].

use crate::controlnet_guide::{ControlGuide, ControlNetUse};
use crate::denoiser::{Denoiser, IpAdapterUse, ItemInputs};
use crate::error::{finite, Error, Result};
use crate::ip_adapter_guide::ImageGuide;
use crate::prompt_weights::PromptSyntax;
use crate::schedulers::{Sampler, SamplerKind, SchedulerConfig};
use crate::sdxl::Sdxl;
use std::time::{Duration, Instant};
use vkdiff_unet::nchw_to_nhwc;

/// How every image of a run is sampled: the settings a batch shares.
#[derive(Clone, Debug, PartialEq)]
pub struct Sampling {
    pub steps: usize,
    pub guidance_scale: f32,
    pub sampler: SamplerKind,
    pub karras: bool,
    pub width: usize,
    pub height: usize,
    pub size_conditioning: SizeConditioning,
    /// img2img: how much of the schedule runs over the init image (diffusers' `strength`);
    /// `None` starts from noise.
    pub strength: Option<f64>,
    pub prompt_syntax: PromptSyntax,
}

/// SDXL's size micro-conditioning, as diffusers' `original_size`, `crops_coords_top_left` and
/// `target_size` (negative rows get the same, diffusers' default). Unset sizes are the image's.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SizeConditioning {
    /// (width, height) of the imagined source image.
    pub original: Option<(usize, usize)>,
    /// (top, left) of the imagined crop, in diffusers' order.
    pub crop_top_left: (usize, usize),
    /// (width, height).
    pub target: Option<(usize, usize)>,
}

impl Sampling {
    /// The UNet's `time_ids`: original (h, w), crop (top, left), target (h, w).
    pub fn time_ids(&self) -> [f32; 6] {
        let c = &self.size_conditioning;
        let own = (self.width, self.height);
        let ((ow, oh), (top, left), (tw, th)) = (c.original.unwrap_or(own), c.crop_top_left, c.target.unwrap_or(own));
        [oh, ow, top, left, th, tw].map(|v| v as f32)
    }

    /// Classifier-free guidance runs a negative row beside each positive one.
    pub fn guided(&self) -> bool {
        self.guidance_scale > 1.0
    }

    /// What is wrong whatever the model: the guidance scale, the step count, a noise schedule
    /// the sampler does not have, a strength that leaves no step.
    pub fn check(&self) -> Result<()> {
        if !self.guidance_scale.is_finite() {
            return Err(Error::Config(format!("--cfg {} is not a number", self.guidance_scale)));
        }
        Sampler::new(self.sampler, &SchedulerConfig::sdxl_base(), self.karras, self.steps)?;
        self.first_step().map(|_| ())
    }

    /// The step img2img starts at (diffusers' `get_timesteps`: the last ⌊steps · strength⌋ steps
    /// run); 0 without an init image.
    pub fn first_step(&self) -> Result<usize> {
        let Some(strength) = self.strength else { return Ok(0) };
        if !(strength > 0.0 && strength <= 1.0) {
            return Err(Error::Config(format!("a strength of {strength} (--strength, --init-strength) must be in (0, 1]")));
        }
        let run = ((self.steps as f64 * strength) as usize).min(self.steps);
        if run == 0 {
            return Err(Error::Config(format!("a strength of {strength} over {} steps runs none of them; raise --steps or the strength", self.steps)));
        }
        Ok(self.steps - run)
    }

    /// The size must be a positive multiple of the model's `multiple` ([`Sdxl::pixel_multiple`]).
    pub fn check_size(&self, multiple: usize) -> Result<()> {
        for (flag, v) in [("--width", self.width), ("--height", self.height)] {
            if v == 0 || !v.is_multiple_of(multiple) {
                return Err(Error::Config(format!("{flag} {v} must be a positive multiple of {multiple} for this model")));
            }
        }
        Ok(())
    }

    /// UNet rows per image: 2 with guidance ([negative, positive]), else 1.
    pub fn rows_per_image(&self) -> usize {
        if self.guided() {
            2
        } else {
            1
        }
    }
}

/// One image's settings (the `vkdiff gen` flags).
#[derive(Clone, Debug)]
pub struct TextToImage {
    pub prompt: String,
    /// `None`: zero negative conditioning where the model asks for it (diffusers' default).
    pub negative_prompt: Option<String>,
    pub seed: u64,
    pub sampling: Sampling,
}

/// 8-bit RGB, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct RgbImage {
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<u8>,
}

/// Where the time went.
#[derive(Clone, Debug, Default)]
pub struct Timings {
    pub text_encoding: Duration,
    /// Preparing the guides (image tokens, ControlNet hint) and recording the passes.
    pub record: Duration,
    pub steps: Vec<Duration>,
    pub vae: Duration,
}

pub struct Generated {
    /// The final latents as the sampler leaves them (before VAE scaling), NCHW [1, C, h, w].
    pub latents: Vec<f32>,
    pub latent_shape: [usize; 4],
    pub image: RgbImage,
    pub timings: Timings,
}

/// What steers a generation beyond the prompt.
#[derive(Default)]
pub struct Guides<'a> {
    pub control: Option<ControlGuide<'a>>,
    pub image: Option<ImageGuide<'a>>,
    /// img2img's init image (with [`Sampling::strength`]).
    pub init: Option<&'a RgbImage>,
}

/// The denoising loop's result, before the VAE.
pub struct Denoised {
    /// NCHW [1, C, h, w], as the sampler leaves them (before VAE scaling).
    pub latents: Vec<f32>,
    pub latent_shape: [usize; 4],
    /// Every stage but the VAE.
    pub timings: Timings,
}

impl Sdxl {
    /// Generates one image; `on_step(done, total)` is called after every denoising step.
    pub fn text_to_image(&self, job: &TextToImage, guides: &Guides, on_step: &mut dyn FnMut(usize, usize)) -> Result<Generated> {
        let Denoised { latents, latent_shape, mut timings } = self.denoise(job, guides, on_step)?;
        let start = Instant::now();
        let image = self.decode(&latents, latent_shape)?;
        timings.vae = start.elapsed();
        Ok(Generated { latents, latent_shape, image, timings })
    }

    /// The latents of one generation, without decoding them.
    pub fn denoise(&self, job: &TextToImage, guides: &Guides, on_step: &mut dyn FnMut(usize, usize)) -> Result<Denoised> {
        let sampling = &job.sampling;
        self.check_sampling(sampling)?;
        let mut timings = Timings::default();
        let start = Instant::now();
        let text = self.encode_prompt_as(sampling.prompt_syntax, &job.prompt, job.negative_prompt.as_deref(), sampling.guided())?;
        timings.text_encoding = start.elapsed();

        let start = Instant::now();
        let ip_tokens = guides.image.as_ref().map(|g| g.tokens(sampling.guided())).transpose()?;
        let control = guides.control.as_ref().map(|g| ControlNetUse { net: g.net, scale: g.scale, start: g.start, end: g.end });
        let ip = guides.image.as_ref().map(|g| IpAdapterUse { adapter: g.adapter, scale: g.scale, images: g.images.len() });
        let denoiser = Denoiser::record(self, sampling, control, ip, 1, text.tokens)?;
        timings.record = start.elapsed();
        let init = guides.init.map(|image| self.encode_init(image, sampling.width, sampling.height)).transpose()?;
        let item = ItemInputs {
            seed: job.seed,
            text: &text,
            control_image: guides.control.as_ref().map(|g| g.image),
            ip_tokens: ip_tokens.as_deref(),
            init: init.as_ref(),
        };
        let out = denoiser.run(&[item], on_step)?;
        timings.record += out.prepare;
        timings.steps = out.steps;
        let latents = out.latents.into_iter().next().expect("one latent per item");
        Ok(Denoised { latents, latent_shape: denoiser.latent_shape(), timings })
    }

    /// Sizes and guidance that this model can sample, checked before any work.
    pub fn check_sampling(&self, sampling: &Sampling) -> Result<()> {
        sampling.check()?;
        sampling.check_size(self.pixel_multiple())
    }

    /// diffusers' image: the decoder's output mapped from [-1, 1], clamped, and rounded to 8 bits.
    pub fn decode(&self, latents: &[f32], [b, c, h, w]: [usize; 4]) -> Result<RgbImage> {
        let factor = self.vae.config().scaling_factor;
        let scaled: Vec<f32> = latents.iter().map(|v| v / factor).collect();
        let (out, [_, height, width, channels]) = self.vae.decode(&nchw_to_nhwc(&scaled, [b, c, h, w]), [b, h, w, c])?;
        finite(&out, &|| "the VAE decoder's output".into())?;
        if channels != 3 {
            return Err(Error::Config(format!("the VAE decodes {channels} channels; an RGB image needs 3")));
        }
        let pixels = out.iter().map(|&v| ((v / 2.0 + 0.5).clamp(0.0, 1.0) * 255.0).round() as u8).collect();
        Ok(RgbImage { width, height, pixels })
    }
}
