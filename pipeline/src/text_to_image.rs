//! Text-to-image as diffusers' `StableDiffusionXLPipeline` runs it: both prompts encoded, the
//! initial noise and any ancestral noise drawn from one torch-compatible generator, classifier-free
//! guidance on a batch of [negative, positive], the scheduler's steps, then the VAE.

use crate::controlnet_guide::{ControlGuide, ControlRun, SharedInputs};
use crate::error::{Error, Result};
use crate::ip_adapter_guide::ImageGuide;
use crate::rng::TorchCpuRng;
use crate::schedulers::{Sampler, SamplerKind};
use crate::sdxl::Sdxl;
use std::time::{Duration, Instant};
use vkdiff_runtime::Dtype;
use vkdiff_unet::{nchw_to_nhwc, nhwc_to_nchw, IpAdapterInput, UNetInputs};

/// One image's settings (the `vkdiff gen` flags).
#[derive(Clone, Debug)]
pub struct TextToImage {
    pub prompt: String,
    /// `None`: zero negative conditioning where the model asks for it (diffusers' default).
    pub negative_prompt: Option<String>,
    pub seed: u64,
    pub steps: usize,
    pub guidance_scale: f32,
    pub sampler: SamplerKind,
    pub karras: bool,
    pub width: usize,
    pub height: usize,
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
    /// Recording the UNet pass once.
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
        let (scale, multiple) = (self.vae_scale(), self.latent_multiple());
        for (flag, v) in [("--width", job.width), ("--height", job.height)] {
            if v == 0 || !v.is_multiple_of(scale * multiple) {
                return Err(Error::Config(format!("{flag} {v} must be a positive multiple of {} for this model", scale * multiple)));
            }
        }
        if !job.guidance_scale.is_finite() {
            return Err(Error::Config(format!("--cfg {} is not a number", job.guidance_scale)));
        }
        let mut sampler = Sampler::new(job.sampler, &self.scheduler, job.karras, job.steps)?;
        let mut timings = Timings::default();
        let (h, w) = (job.height / scale, job.width / scale);
        let channels = self.unet_config.in_channels;
        let guided = job.guidance_scale > 1.0;
        let batch = if guided { 2 } else { 1 };

        let start = Instant::now();
        let (context, pooled) = self.conditioning(job, guided)?;
        timings.text_encoding = start.elapsed();

        let start = Instant::now();
        let dt = self.dtype;
        let ctx = &self.ctx;
        let sample = ctx.zeros(&[batch, h, w, channels], dt)?;
        let timesteps = ctx.zeros(&[batch], Dtype::F32)?;
        let width = self.unet_config.cross_attention_dim;
        let context_t = ctx.upload(&[batch, context.len() / (batch * width), width], dt, &context)?;
        let pooled_t = ctx.upload(&[batch, pooled.len() / batch], dt, &pooled)?;
        let (hh, ww) = (job.height as f32, job.width as f32);
        let time_ids: Vec<f32> = (0..batch).flat_map(|_| [hh, ww, 0.0, 0.0, hh, ww]).collect();
        let time_ids = ctx.upload(&[batch, 6], Dtype::F32, &time_ids)?;
        let shared = SharedInputs { sample: &sample, timesteps: &timesteps, context: &context_t, added: (&pooled_t, &time_ids) };
        let control = guides.control.as_ref().map(|g| ControlRun::record(g, &shared, job.width, job.height, dt)).transpose()?;
        let ip: Vec<IpAdapterInput> = guides.image.iter().map(|g| g.unet_input(guided)).collect::<Result<_>>()?;
        let inputs = UNetInputs {
            sample: &sample,
            timesteps: &timesteps,
            encoder_hidden_states: &context_t,
            added: Some((&pooled_t, &time_ids)),
            control: control.as_ref().map(ControlRun::residuals),
            ip: &ip,
        };
        let pass = self.unet.record(&inputs)?;
        timings.record = start.elapsed();

        let shape = [1, channels, h, w];
        let mut rng = TorchCpuRng::new(job.seed);
        let sigma = sampler.init_noise_sigma();
        let mut latents: Vec<f32> = rng.randn(channels * h * w).into_iter().map(|v| v * sigma).collect();
        let total = sampler.timesteps().len();
        for step in 0..total {
            let start = Instant::now();
            let x_in = nchw_to_nhwc(&sampler.scale_model_input(step, &latents), shape);
            let mut x_batch = x_in.clone();
            if guided {
                x_batch.extend_from_slice(&x_in);
            }
            sample.write(&x_batch)?;
            timesteps.write(&vec![sampler.timesteps()[step]; batch])?;
            if let Some(control) = &control {
                control.step(step, total)?;
            }
            pass.run()?;
            let out = pass.output.download()?;
            let n = out.len() / batch;
            let eps_nhwc: Vec<f32> = if guided {
                let g = job.guidance_scale;
                out[..n].iter().zip(&out[n..]).map(|(&u, &c)| u + g * (c - u)).collect()
            } else {
                out
            };
            let eps = nhwc_to_nchw(&eps_nhwc, [1, h, w, channels]);
            sampler.step(step, &eps, &mut latents, &mut rng);
            timings.steps.push(start.elapsed());
            on_step(step + 1, total);
        }
        Ok(Denoised { latents, latent_shape: shape, timings })
    }
}

impl Sdxl {
    /// diffusers' image: the decoder's output mapped from [-1, 1], clamped, and rounded to 8 bits.
    fn decode(&self, latents: &[f32], [b, c, h, w]: [usize; 4]) -> Result<RgbImage> {
        let factor = self.vae.config().scaling_factor;
        let scaled: Vec<f32> = latents.iter().map(|v| v / factor).collect();
        let (out, [_, height, width, channels]) = self.vae.decode(&nchw_to_nhwc(&scaled, [b, c, h, w]), [b, h, w, c])?;
        if channels != 3 {
            return Err(Error::Config(format!("the VAE decodes {channels} channels; an RGB image needs 3")));
        }
        let pixels = out.iter().map(|&v| ((v / 2.0 + 0.5).clamp(0.0, 1.0) * 255.0).round() as u8).collect();
        Ok(RgbImage { width, height, pixels })
    }
}
