//! What diffusers' `LCMScheduler` and `TCDScheduler` share: timesteps picked from the
//! distillation schedule of `original_inference_steps` (or given), on the variance-preserving
//! latent with no input scaling and unit initial noise. Their steps differ (`lcm.rs`, `tcd.rs`).

use super::config::{PredictionType, SchedulerConfig};
use super::{lcm::LcmStep, tcd::TcdStep, vp_add_noise, Solver};
use crate::rng::TorchCpuRng;
use crate::{Error, Result};
use serde_json::Value;

pub(super) struct ConsistencySchedule {
    /// The training timesteps the steps run at, descending.
    pub timesteps: Vec<usize>,
    /// The same, as the UNet receives them.
    unet_timesteps: Vec<f32>,
    pub alphas_cumprod: Vec<f32>,
    pub prediction: PredictionType,
}

/// How a consistency sampler steps.
pub(super) enum ConsistencyStep {
    Lcm(LcmStep),
    Tcd(TcdStep),
}

/// An LCM or TCD sampler: the shared schedule and its own step.
pub(super) struct Consistency {
    schedule: ConsistencySchedule,
    step: ConsistencyStep,
}

impl Consistency {
    /// `set_timesteps(steps)`: `steps` of the `original_inference_steps` distillation timesteps
    /// (k·i − 1, k = train / original), evenly spaced by index from the noisiest; or `custom`.
    pub(super) fn new(
        config: &SchedulerConfig,
        steps: usize,
        custom: Option<&[u32]>,
        step: ConsistencyStep,
    ) -> Result<Consistency> {
        config.only("thresholding", &[Value::Bool(false)])?;
        let name = match step {
            ConsistencyStep::Lcm(_) => "lcm",
            ConsistencyStep::Tcd(_) => "tcd",
        };
        let prediction = config.prediction()?;
        let alphas_cumprod = config.alphas_cumprod()?;
        let train = alphas_cumprod.len();
        let timesteps: Vec<usize> = match custom {
            Some(custom) => custom.iter().map(|&t| t as usize).collect(),
            None => distilled_timesteps(config, name, steps, train)?,
        };
        let unet_timesteps = timesteps.iter().map(|&t| t as f32).collect();
        Ok(Consistency {
            schedule: ConsistencySchedule { timesteps, unet_timesteps, alphas_cumprod, prediction },
            step,
        })
    }
}

impl ConsistencySchedule {
    /// ᾱ at the timestep of `step`.
    pub(super) fn alpha(&self, step: usize) -> f32 {
        self.alphas_cumprod[self.timesteps[step]]
    }

    /// Whether `step` is the schedule's last, where no fresh noise is drawn.
    pub(super) fn is_last(&self, step: usize) -> bool {
        step + 1 == self.timesteps.len()
    }
}

impl Solver for Consistency {
    fn timesteps(&self) -> &[f32] {
        &self.schedule.unet_timesteps
    }

    fn sigmas(&self) -> Option<&[f32]> {
        None
    }

    fn init_noise_sigma(&self) -> f32 {
        1.0
    }

    fn scale_model_input(&self, _step: usize, x: &[f32]) -> Vec<f32> {
        x.to_vec()
    }

    fn add_noise(&self, step: usize, x0: &[f32], noise: &[f32]) -> Vec<f32> {
        vp_add_noise(self.schedule.alpha(step), x0, noise)
    }

    fn step(&mut self, step: usize, out: &[f32], x: &mut [f32], rng: &mut TorchCpuRng) {
        match &self.step {
            ConsistencyStep::Lcm(lcm) => lcm.step(&self.schedule, step, out, x, rng),
            ConsistencyStep::Tcd(tcd) => tcd.step(&self.schedule, step, out, x, rng),
        }
    }
}

fn distilled_timesteps(config: &SchedulerConfig, name: &str, steps: usize, train: usize) -> Result<Vec<usize>> {
    let original = config.integer("original_inference_steps", 50)? as usize;
    if original == 0 || original > train {
        return Err(config.unsupported("original_inference_steps", &format!("(1 to {train})")));
    }
    if steps > original {
        return Err(Error::Config(format!(
            "{name}: {steps} steps exceed original_inference_steps {original}, the schedule its timesteps are picked \
                from (give fewer steps, or the timesteps themselves)"
        )));
    }
    let k = train / original;
    let origin: Vec<usize> = (1..=original).rev().map(|i| i * k - 1).collect();
    // np.floor(np.linspace(0, len, steps, endpoint=False)): index i · (len / steps).
    let stride = origin.len() as f64 / steps as f64;
    Ok((0..steps).map(|i| origin[(i as f64 * stride).floor() as usize]).collect())
}
