//! diffusers `EulerAncestralDiscreteScheduler` (η = 1): an Euler step down to σ_down, then fresh
//! noise of scale σ_up, drawn at every step (the last one, where σ_up = 0, included).

use super::config::{Prediction, SchedulerConfig};
use super::euler_discrete::sigma_schedule;
use super::{add_sigma_noise, denoised, euler_init_noise_sigma, scale_by_sigma, Solver};
use crate::rng::TorchCpuRng;
use crate::Result;

pub(super) struct EulerAncestralDiscrete {
    timesteps: Vec<f32>,
    sigmas: Vec<f32>,
    init_noise_sigma: f32,
    prediction: Prediction,
}

impl EulerAncestralDiscrete {
    pub(super) fn new(config: &SchedulerConfig, steps: usize) -> Result<EulerAncestralDiscrete> {
        let prediction = config.prediction()?;
        let spacing = config.spacing("linspace")?;
        let (timesteps, sigmas) = sigma_schedule(config, spacing, steps, false, false)?;
        let init_noise_sigma = euler_init_noise_sigma(&sigmas, spacing);
        Ok(EulerAncestralDiscrete { timesteps, sigmas, init_noise_sigma, prediction })
    }
}

impl Solver for EulerAncestralDiscrete {
    fn timesteps(&self) -> &[f32] {
        &self.timesteps
    }

    fn sigmas(&self) -> Option<&[f32]> {
        Some(&self.sigmas)
    }

    fn add_noise(&self, step: usize, x0: &[f32], noise: &[f32]) -> Vec<f32> {
        add_sigma_noise(self.sigmas[step], x0, noise)
    }

    fn init_noise_sigma(&self) -> f32 {
        self.init_noise_sigma
    }

    fn scale_model_input(&self, step: usize, x: &[f32]) -> Vec<f32> {
        scale_by_sigma(x, self.sigmas[step])
    }

    fn step(&mut self, step: usize, eps: &[f32], x: &mut [f32], rng: &mut TorchCpuRng) {
        let (from, to) = (self.sigmas[step], self.sigmas[step + 1]);
        let sigma_up = (to * to * (from * from - to * to) / (from * from)).sqrt();
        let sigma_down = (to * to - sigma_up * sigma_up).sqrt();
        let dt = sigma_down - from;
        let noise = rng.randn(x.len());
        for ((x, &eps), noise) in x.iter_mut().zip(eps).zip(noise) {
            let derivative = (*x - denoised(self.prediction, from, *x, eps)) / from;
            *x = (*x + derivative * dt) + noise * sigma_up;
        }
    }
}
