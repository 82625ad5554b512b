//! diffusers' `EulerDiscreteScheduler` without churn (x ← x + (x − x₀)/σ · (σ_next − σ)) and
//! `EulerAncestralDiscreteScheduler` (η = 1: an Euler step down to σ_down, then fresh noise of
//! scale σ_up, drawn at every step, the last one, where σ_up = 0, included): one σ schedule, two
//! steps.

use super::config::{PredictionType, SchedulerConfig, TimestepSpacing};
use super::{
    add_sigma_noise, denoised, euler_init_noise_sigma, interp, karras_sigmas, log_sigmas, scale_by_sigma, sigma_to_t,
    spaced_timesteps, train_sigmas, Solver,
};
use crate::rng::TorchCpuRng;
use crate::Result;

pub(super) struct EulerDiscrete {
    timesteps: Vec<f32>,
    sigmas: Vec<f32>,
    init_noise_sigma: f32,
    prediction: PredictionType,
    /// Euler-ancestral's step.
    ancestral: bool,
}

impl EulerDiscrete {
    /// `custom`: `set_timesteps(timesteps=…)`'s schedule in place of the spaced one.
    pub(super) fn new(
        config: &SchedulerConfig,
        karras: bool,
        steps: usize,
        custom: Option<&[u32]>,
    ) -> Result<EulerDiscrete> {
        config.only("interpolation_type", &["linear".into()])?;
        config.only("use_exponential_sigmas", &[false.into()])?;
        config.only("use_beta_sigmas", &[false.into()])?;
        let prediction = config.prediction()?;
        if prediction == PredictionType::V {
            // Continuous timesteps change what the UNet is fed only for v-prediction.
            config.only("timestep_type", &["discrete".into()])?;
        }
        let spacing = config.spacing("linspace")?;
        let (timesteps, sigmas) = sigma_schedule(config, spacing, steps, custom, karras, config.final_sigma_is_min()?)?;
        let init_noise_sigma = euler_init_noise_sigma(&sigmas, spacing);
        Ok(EulerDiscrete { timesteps, sigmas, init_noise_sigma, prediction, ancestral: false })
    }

    /// `EulerAncestralDiscreteScheduler`: the same schedule, without Karras or a `sigma_min` end.
    pub(super) fn ancestral(config: &SchedulerConfig, steps: usize) -> Result<EulerDiscrete> {
        let prediction = config.prediction()?;
        let spacing = config.spacing("linspace")?;
        let (timesteps, sigmas) = sigma_schedule(config, spacing, steps, None, false, false)?;
        let init_noise_sigma = euler_init_noise_sigma(&sigmas, spacing);
        Ok(EulerDiscrete { timesteps, sigmas, init_noise_sigma, prediction, ancestral: true })
    }
}

/// The timesteps and σ's (with the final one appended) of `EulerDiscreteScheduler.set_timesteps`.
fn sigma_schedule(
    config: &SchedulerConfig,
    spacing: TimestepSpacing,
    steps: usize,
    custom: Option<&[u32]>,
    karras: bool,
    final_sigma_min: bool,
) -> Result<(Vec<f32>, Vec<f32>)> {
    let train = train_sigmas(&config.alphas_cumprod()?);
    let mut timesteps: Vec<f32> = match custom {
        Some(custom) => custom.iter().map(|&t| t as f32).collect(),
        None => {
            spaced_timesteps(spacing, steps, train.len(), config.steps_offset()?).iter().map(|&t| t as f32).collect()
        }
    };
    // σ linearly interpolated in t (numpy, float64) at the float32 timesteps.
    let mut sigmas: Vec<f64> = timesteps.iter().map(|&t| interp(f64::from(t), &train)).collect();
    if karras {
        // Re-spaced between the ends of that interpolated range, and fed to the UNet as the
        // fractional timesteps of those σ's.
        let (sigma_min, sigma_max) = config.karras_range()?;
        sigmas = karras_sigmas(sigma_min.unwrap_or(sigmas[sigmas.len() - 1]), sigma_max.unwrap_or(sigmas[0]), steps);
        let logs = log_sigmas(&train);
        timesteps = sigmas.iter().map(|&s| sigma_to_t(s, &logs) as f32).collect();
    }
    let last = if final_sigma_min { train[0] } else { 0.0 };
    Ok((timesteps, sigmas.iter().map(|&s| s as f32).chain([last]).collect()))
}

impl Solver for EulerDiscrete {
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
        if !self.ancestral {
            let dt = to - from;
            for (x, &eps) in x.iter_mut().zip(eps) {
                let derivative = (*x - denoised(self.prediction, from, *x, eps)) / from;
                *x += derivative * dt;
            }
            return;
        }
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
