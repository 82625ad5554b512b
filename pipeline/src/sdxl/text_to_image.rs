//! Text-to-image as diffusers' `StableDiffusionXLPipeline` runs it: both prompts encoded, the
//! initial noise and any ancestral noise drawn from one torch-compatible generator, classifier-free
//! guidance on a batch of [negative, positive], the scheduler's steps, then the VAE. One image is a
//! batch of one through [`Denoiser`].

use crate::error::{finite, Error, Result};
use crate::sdxl::controlnet_guide::{ControlGuide, ControlNetUse};
use crate::sdxl::denoiser::{Denoiser, IpAdapterUse, ItemInputs};
use crate::sdxl::Sdxl;
use crate::sdxl::{Conditioning, ImageGuide, Regions};
use crate::settings::sampling::{Sampling, TextToImage};
use crate::RgbImage;
use std::time::{Duration, Instant};
use vkdiff_networks::nchw_to_nhwc;

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
    /// The ControlNets, their residuals summed (none: no ControlNet).
    pub control: Vec<ControlGuide<'a>>,
    pub image: Option<ImageGuide<'a>>,
    /// img2img's init image (with [`Sampling::strength`]).
    pub init: Option<&'a RgbImage>,
    /// Region prompts over the prompt.
    pub regions: Option<&'a Regions<'a>>,
    /// img2img with a strength per latent pixel ([`ItemInputs::strength`]).
    pub strength: Option<&'a [f64]>,
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
    /// `job.sampling` must have passed [`Sdxl::check_sampling`] (the entries, `GenJob` and
    /// `DatasetSettings`, check it once, before any model loads).
    pub fn text_to_image(
        &self,
        job: &TextToImage,
        guides: &Guides,
        on_step: &mut dyn FnMut(usize, usize),
    ) -> Result<Generated> {
        let (mut out, encoding) =
            self.with_encoding(job, |text| self.text_to_image_encoded(job, text, guides, on_step))?;
        out.timings.text_encoding = encoding;
        Ok(out)
    }

    /// Encodes `job`'s prompts and runs `then` on them; with the encoding's time.
    fn with_encoding<T>(
        &self,
        job: &TextToImage,
        then: impl FnOnce(&Conditioning) -> Result<T>,
    ) -> Result<(T, Duration)> {
        let start = Instant::now();
        let text = self.encode_job(job)?;
        let encoding = start.elapsed();
        Ok((then(&text)?, encoding))
    }

    /// [`Sdxl::text_to_image`] with the prompts already encoded ([`Sdxl::encode_job`]), so the
    /// text encoders may be released before the denoising takes its memory.
    pub fn text_to_image_encoded(
        &self,
        job: &TextToImage,
        text: &Conditioning,
        guides: &Guides,
        on_step: &mut dyn FnMut(usize, usize),
    ) -> Result<Generated> {
        let Denoised { latents, latent_shape, mut timings } = self.denoise_encoded(job, text, guides, on_step)?;
        let start = Instant::now();
        let image = self.decode(&latents, latent_shape)?;
        timings.vae = start.elapsed();
        Ok(Generated { latents, latent_shape, image, timings })
    }

    /// Both prompts of `job`, encoded as its sampling says.
    pub fn encode_job(&self, job: &TextToImage) -> Result<Conditioning> {
        let sampling = &job.sampling;
        self.encode_prompt_as(sampling.prompt_syntax, &job.prompt, job.negative_prompt.as_deref(), sampling.guided())
    }

    /// The latents of one generation, without decoding them; the sampling is checked as for
    /// [`Sdxl::text_to_image`].
    pub fn denoise(
        &self,
        job: &TextToImage,
        guides: &Guides,
        on_step: &mut dyn FnMut(usize, usize),
    ) -> Result<Denoised> {
        let (mut out, encoding) = self.with_encoding(job, |text| self.denoise_encoded(job, text, guides, on_step))?;
        out.timings.text_encoding = encoding;
        Ok(out)
    }

    /// [`Sdxl::denoise`] with the prompts already encoded.
    pub fn denoise_encoded(
        &self,
        job: &TextToImage,
        text: &Conditioning,
        guides: &Guides,
        on_step: &mut dyn FnMut(usize, usize),
    ) -> Result<Denoised> {
        let sampling = &job.sampling;
        let mut timings = Timings::default();
        let start = Instant::now();
        let ip_tokens = guides.image.as_ref().map(|g| g.tokens(sampling.guided())).transpose()?;
        let controls: Vec<ControlNetUse> = guides.control.iter().map(|g| g.use_).collect();
        let ip =
            guides.image.as_ref().map(|g| IpAdapterUse { adapter: g.adapter, scale: g.scale, images: g.images.len() });
        let regions = guides.regions.map_or(0, |r| r.texts.len());
        let denoiser = Denoiser::record(self, sampling, &controls, ip, 1, text.tokens, regions)?;
        timings.record = start.elapsed();
        let init = guides.init.map(|image| self.encode_init(image, sampling.width, sampling.height)).transpose()?;
        let item = ItemInputs {
            seed: job.seed,
            text,
            control_images: guides.control.iter().map(|g| g.images.clone()).collect(),
            ip_tokens: ip_tokens.as_deref(),
            init: init.as_ref(),
            regions: guides.regions,
            strength: guides.strength,
        };
        let out = denoiser.run(&[item], on_step)?;
        timings.record += out.prepare;
        timings.steps = out.steps;
        let latents = out.latents.into_iter().next().expect("one latent per item");
        Ok(Denoised { latents, latent_shape: denoiser.latent_shape(), timings })
    }

    /// Sizes and guidance that this model can sample, checked before any work.
    pub fn check_sampling(&self, sampling: &Sampling) -> Result<()> {
        sampling.check(&self.scheduler)?;
        sampling.check_size(self.pixel_multiple())
    }

    /// diffusers' image: the decoder's output mapped from [-1, 1], clamped, and rounded to 8 bits;
    /// decoded whole or in the tiles [`Sdxl::plan_vae`] chose.
    pub fn decode(&self, latents: &[f32], [b, c, h, w]: [usize; 4]) -> Result<RgbImage> {
        let factor = self.vae.config().scaling_factor;
        let scaled: Vec<f32> = latents.iter().map(|v| v / factor).collect();
        let (latents, shape) = (nchw_to_nhwc(&scaled, [b, c, h, w]), [b, h, w, c]);
        let (out, [_, height, width, channels]) = match self.vae_tiling() {
            Some(tiling) => self.vae.decode_tiled(&latents, shape, tiling)?,
            None => self.vae.decode(&latents, shape)?,
        };
        finite(&out, &|| "the VAE decoder's output".into())?;
        if channels != 3 {
            return Err(Error::Config(format!("the VAE decodes {channels} channels; an RGB image needs 3")));
        }
        let pixels = out.iter().map(|&v| ((v / 2.0 + 0.5).clamp(0.0, 1.0) * 255.0).round() as u8).collect();
        Ok(RgbImage { width, height, pixels })
    }
}
