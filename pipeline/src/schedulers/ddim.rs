//! diffusers `DDIMScheduler` with η = 0: x₀ and ε from the model output, then
//! x_prev = √ᾱ_prev·x₀ + √(1 − ᾱ_prev)·ε, on the variance-preserving latent.

use super::config::{PredictionType, SchedulerConfig, TimestepSpacing};
use super::{numpy_linspace, spaced_timesteps, vp_add_noise, vp_prediction, Solver};
use crate::rng::TorchCpuRng;
use crate::{Error, Result};
use serde_json::Value;

pub(super) struct Ddim {
    timesteps: Vec<f32>,
    alphas_cumprod: Vec<f32>,
    /// ᾱ used once the previous timestep falls below 0 (`set_alpha_to_one`: 1, else ᾱ_0).
    final_alpha_cumprod: f32,
    /// `num_train_timesteps // steps`: how far back "previous" is, whatever the spacing.
    stride: i64,
    prediction: PredictionType,
    /// x₀ is clamped to ±this (`clip_sample`).
    clip: Option<f32>,
}

impl Ddim {
    pub(super) fn new(config: &SchedulerConfig, steps: usize) -> Result<Ddim> {
        config.only("thresholding", &[Value::Bool(false)])?;
        let prediction = config.prediction()?;
        let alphas_cumprod = config.alphas_cumprod()?;
        let train = alphas_cumprod.len();
        if steps > train {
            return Err(Error::Config(format!("ddim: {steps} steps exceed the {train} training timesteps")));
        }
        let timesteps: Vec<f64> = match config.spacing("leading")? {
            TimestepSpacing::Linspace => {
                numpy_linspace(0.0, (train - 1) as f64, steps).iter().rev().map(|t| t.round_ties_even()).collect()
            }
            spacing => spaced_timesteps(spacing, steps, train, config.steps_offset()?),
        };
        // diffusers would index ᾱ from the end (or past it) here.
        if let Some(t) = timesteps.iter().find(|&&t| t < 0.0 || t >= train as f64) {
            return Err(Error::Config(format!(
                "ddim: {steps} steps with this spacing give timestep {t}, outside 0..{train}"
            )));
        }
        let final_alpha_cumprod = if config.flag("set_alpha_to_one", true)? { 1.0 } else { alphas_cumprod[0] };
        let clip = config
            .flag("clip_sample", true)?
            .then(|| config.number("clip_sample_range", 1.0))
            .transpose()?
            .map(|r| r as f32);
        Ok(Ddim {
            timesteps: timesteps.iter().map(|&t| t as f32).collect(),
            alphas_cumprod,
            final_alpha_cumprod,
            stride: (train / steps) as i64,
            prediction,
            clip,
        })
    }
}

impl Solver for Ddim {
    fn timesteps(&self) -> &[f32] {
        &self.timesteps
    }

    fn sigmas(&self) -> Option<&[f32]> {
        None
    }

    fn add_noise(&self, step: usize, x0: &[f32], noise: &[f32]) -> Vec<f32> {
        vp_add_noise(self.alphas_cumprod[self.timesteps[step] as usize], x0, noise)
    }

    fn init_noise_sigma(&self) -> f32 {
        1.0
    }

    fn scale_model_input(&self, _step: usize, x: &[f32]) -> Vec<f32> {
        x.to_vec()
    }

    fn step(&mut self, step: usize, eps: &[f32], x: &mut [f32], _rng: &mut TorchCpuRng) {
        let t = self.timesteps[step] as i64;
        let prev = t - self.stride;
        let alpha = self.alphas_cumprod[t as usize];
        let alpha_prev = if prev >= 0 { self.alphas_cumprod[prev as usize] } else { self.final_alpha_cumprod };
        let (sqrt_alpha, sqrt_beta) = (alpha.sqrt(), (1.0 - alpha).sqrt());
        // η = 0, so the direction term keeps all of 1 − ᾱ_prev.
        let (sqrt_alpha_prev, direction) = (alpha_prev.sqrt(), (1.0 - alpha_prev).sqrt());
        for (x, &e) in x.iter_mut().zip(eps) {
            let (x0, eps) = vp_prediction(self.prediction, sqrt_alpha, sqrt_beta, *x, e);
            let x0 = self.clip.map_or(x0, |r| x0.max(-r).min(r));
            *x = sqrt_alpha_prev * x0 + direction * eps;
        }
    }
}
