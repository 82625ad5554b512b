//! Batched denoising: B images per UNet pass (2B rows with guidance, laid out as diffusers
//! concatenates them: every negative row, then every positive row; then, with region prompts,
//! every image's first region's row, and so on). The UNet and ControlNet are
//! recorded once per batch shape; each batch writes its inputs into the recorded tensors and
//! replays the passes. Each image keeps its own generator, sampler state and latents, so an
//! image's result does not depend on the images beside it.

use crate::error::{finite, Error, Result};
use crate::rng::TorchCpuRng;
use crate::sdxl::controlnet_guide::{ControlNetUse, ControlRun, SharedInputs};
use crate::sdxl::prompt_encoding::Conditioning;
use crate::sdxl::regions::{blend, HeldLatents, Regions};
use crate::sdxl::InitLatents;
use crate::sdxl::Sdxl;
use crate::settings::ip_scale::IpScale;
use crate::settings::sampling::Sampling;
use crate::RgbImage;
use std::time::{Duration, Instant};
use vkdiff_networks::{nchw_to_nhwc, nhwc_to_nchw, IpAdapter, IpAdapterInput, UNetInputs, UNetPass};
use vkdiff_runtime::{Dtype, Tensor};

/// An IP-Adapter and its weights, for images that each have `images` style images.
#[derive(Clone, Copy)]
pub struct IpAdapterUse<'a> {
    pub adapter: &'a IpAdapter,
    pub scale: &'a IpScale,
    pub images: usize,
}

/// One image's inputs, prepared on the host.
pub struct ItemInputs<'a> {
    /// Seed of the image's own `torch.Generator("cpu")`.
    pub seed: u64,
    pub text: &'a Conditioning,
    /// Each ControlNet's conditioning images (one per control it sees), in the batch's
    /// ControlNets' order.
    pub control_images: Vec<Vec<&'a RgbImage>>,
    /// The image tokens of its rows ([`crate::ImageGuide::tokens`]), when it has an IP-Adapter.
    pub ip_tokens: Option<&'a [f32]>,
    /// img2img: the encoded init image, when the batch samples with a strength.
    pub init: Option<&'a InitLatents>,
    /// Its region prompts, when the batch was recorded for them.
    pub regions: Option<&'a Regions<'a>>,
    /// img2img with a strength per latent pixel, over the batch's strength (in [0, 1]): pixels
    /// below a step's threshold are held on the init latent's path.
    pub strength: Option<&'a [f64]>,
}

/// A batch's latents and where its time went.
pub struct BatchOutput {
    /// NCHW [1, C, h, w] per image, as the sampler leaves them (before VAE scaling).
    pub latents: Vec<Vec<f32>>,
    /// Writing the inputs and encoding the ControlNet hint.
    pub prepare: Duration,
    pub steps: Vec<Duration>,
}

/// The UNet (and ControlNet) recorded for `batch` images of one size.
pub struct Denoiser<'m> {
    model: &'m Sdxl,
    sampling: Sampling,
    batch: usize,
    /// Latent height, width, channels.
    latent: [usize; 3],
    sample: Tensor,
    timesteps: Tensor,
    context: Tensor,
    pooled: Tensor,
    _time_ids: Tensor,
    /// Region prompts per image: rows beyond the negative and positive ones.
    regions: usize,
    /// The ControlNets; the first holds the residuals the others add onto and the UNet reads.
    controls: Vec<ControlRun<'m>>,
    ip: Vec<IpAdapterInput>,
    pass: UNetPass,
}

impl<'m> Denoiser<'m> {
    /// Records the passes for `batch` images sampled as `sampling` says, with prompts of
    /// `tokens` tokens ([`Conditioning::tokens`]) and `regions` region prompts each, steered by
    /// `controls` (summed) and `ip`.
    pub fn record(
        model: &'m Sdxl,
        sampling: &Sampling,
        controls: &[ControlNetUse<'m>],
        ip: Option<IpAdapterUse<'m>>,
        batch: usize,
        tokens: usize,
        regions: usize,
    ) -> Result<Denoiser<'m>> {
        debug_assert!(model.check_sampling(sampling).is_ok(), "the entries check the sampling before loading");
        assert!(batch > 0, "a denoiser runs batches of at least one image (the entries check the batch)");
        let scale = model.vae_scale();
        let latent = [sampling.height / scale, sampling.width / scale, model.unet_config.in_channels];
        let rows = batch * (sampling.rows_per_image() + regions);
        let (ctx, dt) = (&model.ctx, model.dtype);
        let sample = ctx.zeros(&[rows, latent[0], latent[1], latent[2]], dt)?;
        let timesteps = ctx.zeros(&[rows], Dtype::F32)?;
        let context = ctx.zeros(&[rows, tokens, model.unet_config.cross_attention_dim], dt)?;
        let pooled_width = model.text_widths.1;
        let pooled = ctx.zeros(&[rows, pooled_width], dt)?;
        let time_ids: Vec<f32> = (0..rows).flat_map(|_| sampling.time_ids()).collect();
        let time_ids = ctx.upload(&[rows, 6], Dtype::F32, &time_ids)?;
        let shared =
            SharedInputs { sample: &sample, timesteps: &timesteps, context: &context, added: (&pooled, &time_ids) };
        let mut runs: Vec<ControlRun> = Vec::with_capacity(controls.len());
        for &control in controls {
            let add_to = runs.first().map(ControlRun::residuals);
            let run = ControlRun::record(control, &shared, add_to)?;
            runs.push(run);
        }
        let ip = match ip {
            Some(use_) => {
                let width = model.unet_config.cross_attention_dim;
                let zeros = vec![0.0; rows * use_.images * use_.adapter.num_tokens() * width];
                vec![use_.adapter.unet_input(&zeros, rows, use_.scale.per_layer(model.unet.cross_attentions())?)?]
            }
            None => Vec::new(),
        };
        let inputs = UNetInputs {
            sample: &sample,
            timesteps: &timesteps,
            encoder_hidden_states: &context,
            added: Some((&pooled, &time_ids)),
            control: runs.first().map(ControlRun::residuals),
            ip: &ip,
        };
        let pass = model.unet.record(&inputs)?;
        Ok(Denoiser {
            model,
            sampling: sampling.clone(),
            batch,
            latent,
            sample,
            timesteps,
            context,
            pooled,
            _time_ids: time_ids,
            regions,
            controls: runs,
            ip,
            pass,
        })
    }

    /// UNet rows per image: negative (with guidance), positive, one per region prompt.
    fn rows_per_image(&self) -> usize {
        self.sampling.rows_per_image() + self.regions
    }

    /// Images per pass.
    pub fn batch(&self) -> usize {
        self.batch
    }

    /// NCHW shape of one image's latents.
    pub fn latent_shape(&self) -> [usize; 4] {
        let [h, w, c] = self.latent;
        [1, c, h, w]
    }

    /// Denoises exactly [`Denoiser::batch`] images; `on_step(done, total)` after every step.
    pub fn run(&self, items: &[ItemInputs], on_step: &mut dyn FnMut(usize, usize)) -> Result<BatchOutput> {
        if items.len() != self.batch {
            return Err(Error::Config(format!("{} images for a pass recorded for {}", items.len(), self.batch)));
        }
        let start = Instant::now();
        self.write_conditioning(items)?;
        let prepare = start.elapsed();

        let [h, w, c] = self.latent;
        let n = c * h * w;
        let first = self.sampling.first_step()?;
        let mut samplers = Vec::with_capacity(items.len());
        let mut rngs = Vec::with_capacity(items.len());
        let mut latents = Vec::with_capacity(items.len());
        let mut holds = Vec::with_capacity(items.len());
        for item in items {
            let sampler = self.sampling.sampler(&self.model.scheduler)?;
            let mut rng = TorchCpuRng::new(item.seed);
            latents.push(match (item.init, self.sampling.strength) {
                (None, None) => {
                    let sigma = sampler.init_noise_sigma();
                    rng.randn(n).into_iter().map(|v| v * sigma).collect::<Vec<f32>>()
                }
                (Some(init), Some(_)) if init.mean.len() == n && init.std.len() == n => {
                    // diffusers: latent_dist.sample(generator), scaled, then noise from the same generator.
                    let scaling = self.model.vae.config().scaling_factor;
                    let x0: Vec<f32> = init
                        .mean
                        .iter()
                        .zip(&init.std)
                        .zip(rng.randn(n))
                        .map(|((m, s), e)| (m + s * e) * scaling)
                        .collect();
                    let noise = rng.randn(n);
                    let noised = sampler.add_noise(first, &x0, &noise);
                    holds.push(item.strength.map(|relative| HeldLatents { relative, x0, noise }));
                    noised
                }
                (Some(init), Some(_)) => {
                    return Err(Error::Config(format!(
                        "init latents of {} values for a latent of {n}",
                        init.mean.len()
                    )))
                }
                _ => {
                    return Err(Error::Config(
                        "img2img needs an init image and a strength for every image of the batch".into(),
                    ))
                }
            });
            samplers.push(sampler);
            rngs.push(rng);
        }
        if holds.len() != items.len() && items.iter().any(|i| i.strength.is_some()) {
            return Err(Error::Config("a strength per region needs img2img's init image".into()));
        }
        holds.resize_with(items.len(), || None);
        let prediction = match self.sampling.schedule.prediction {
            Some(p) => p,
            None => self.model.scheduler.prediction()?,
        };
        let timesteps = samplers[0].timesteps().to_vec();
        let total = timesteps.len();
        let guided = self.sampling.guided();
        let per_image = self.rows_per_image();
        let mut steps = Vec::with_capacity(total - first);
        for (step, &t) in timesteps.iter().enumerate().skip(first) {
            let start = Instant::now();
            let held: Vec<Option<Vec<bool>>> =
                holds.iter().map(|hold| hold.as_ref().and_then(|hold| hold.held(t, timesteps[first]))).collect();
            for (((x, sampler), hold), held) in latents.iter_mut().zip(&samplers).zip(&holds).zip(&held) {
                if let (Some(hold), Some(held)) = (hold, held) {
                    HeldLatents::hold_input(held, x, &sampler.add_noise(step, &hold.x0, &hold.noise));
                }
            }
            let mut x_batch = Vec::with_capacity(self.sample.numel());
            for (sampler, x) in samplers.iter().zip(&latents) {
                x_batch.extend(nchw_to_nhwc(&sampler.scale_model_input(step, x), [1, c, h, w]));
            }
            let block = x_batch.len();
            for _ in 1..per_image {
                x_batch.extend_from_within(..block);
            }
            self.sample.write(&x_batch)?;
            self.timesteps.write(&vec![t; self.timesteps.numel()])?;
            for control in &self.controls {
                control.step(step, total)?;
            }
            self.pass.run()?;
            let out = self.pass.output.download()?;
            finite(&out, &|| format!("the UNet's output at step {} of {total}", step + 1))?;
            let row = |r: usize, i: usize| &out[(r * self.batch + i) * n..(r * self.batch + i + 1) * n];
            for (i, ((sampler, x), rng)) in samplers.iter_mut().zip(&mut latents).zip(&mut rngs).enumerate() {
                let positive_row = usize::from(guided);
                let blended;
                let p = match items[i].regions {
                    Some(regions) => {
                        let rows: Vec<&[f32]> = (positive_row..per_image).map(|r| row(r, i)).collect();
                        blended = blend(&rows, &regions.masks, c);
                        &blended[..]
                    }
                    None => row(positive_row, i),
                };
                let eps_nhwc: Vec<f32> = if guided {
                    let g = self.sampling.guidance_scale;
                    row(0, i).iter().zip(p).map(|(&u, &p)| u + g * (p - u)).collect()
                } else {
                    p.to_vec()
                };
                let mut eps = nhwc_to_nchw(&eps_nhwc, [1, h, w, c]);
                if let (Some(hold), Some(held)) = (&holds[i], &held[i]) {
                    hold.hold_output(held, prediction, &mut eps)?;
                }
                sampler.step(step, &eps, x, rng);
            }
            steps.push(start.elapsed());
            on_step(step + 1 - first, total - first);
        }
        Ok(BatchOutput { latents, prepare, steps })
    }

    /// Text, image tokens and control images of every row (all negatives, then all positives),
    /// and the keys and values projected from them.
    fn write_conditioning(&self, items: &[ItemInputs]) -> Result<()> {
        let per_image = self.rows_per_image();
        let row = |t: &Tensor| t.numel() / t.shape()[0];
        let texts = (items.iter())
            .map(|i| Regions::rows(i.text, i.regions, self.regions))
            .collect::<Result<Vec<(Vec<f32>, Vec<f32>)>>>()?;
        let contexts: Vec<Option<&[f32]>> = texts.iter().map(|(c, _)| Some(&c[..])).collect();
        self.context.write(&by_row(&contexts, per_image, row(&self.context), "prompt encoding")?)?;
        let pooled: Vec<Option<&[f32]>> = texts.iter().map(|(_, p)| Some(&p[..])).collect();
        self.pooled.write(&by_row(&pooled, per_image, row(&self.pooled), "pooled prompt encoding")?)?;
        if let Some(ip) = self.ip.first() {
            // Every region's row sees the image tokens the positive row sees.
            let width = row(&ip.tokens);
            let tokens: Vec<Option<Vec<f32>>> = (items.iter())
                .map(|i| {
                    i.ip_tokens.map(|t| {
                        let positive = &t[t.len().saturating_sub(width)..];
                        let mut all = t.to_vec();
                        (0..self.regions).for_each(|_| all.extend_from_slice(positive));
                        all
                    })
                })
                .collect();
            let tokens: Vec<Option<&[f32]>> = tokens.iter().map(Option::as_deref).collect();
            ip.tokens.write(&by_row(&tokens, per_image, width, "IP-Adapter image tokens")?)?;
        }
        for item in items {
            let given: Vec<usize> = item.control_images.iter().map(Vec::len).collect();
            let wanted: Vec<usize> = self.controls.iter().map(ControlRun::images_per_item).collect();
            if given != wanted {
                return Err(Error::Config(format!(
                    "an image of the batch has {given:?} control images for ControlNets that see {wanted:?}"
                )));
            }
        }
        for (k, control) in self.controls.iter().enumerate() {
            let images: Vec<&[&RgbImage]> = items.iter().map(|i| i.control_images[k].as_slice()).collect();
            control.set_images(&images, per_image, self.sampling.width, self.sampling.height)?;
            control.project_conditioning()?;
        }
        Ok(self.pass.project_conditioning()?)
    }
}

/// Rows of `row_len` values from every item's `per_image` rows: first row of every item, then the
/// second row of every item.
fn by_row(items: &[Option<&[f32]>], per_image: usize, row_len: usize, what: &str) -> Result<Vec<f32>> {
    let mut out = Vec::with_capacity(row_len * per_image * items.len());
    for r in 0..per_image {
        for item in items {
            let v = item.ok_or_else(|| Error::Config(format!("an image of the batch has no {what}")))?;
            if v.len() != row_len * per_image {
                return Err(Error::Config(format!(
                    "{what}: {} values where the recorded pass takes {}",
                    v.len(),
                    row_len * per_image
                )));
            }
            out.extend_from_slice(&v[r * row_len..(r + 1) * row_len]);
        }
    }
    Ok(out)
}
