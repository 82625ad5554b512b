//! diffusers' `LCMScheduler` step: the consistency function's x₀ (the model's x₀ blended with the
//! latent by the boundary-condition scalings c_skip and c_out), then, except at the last step,
//! that x₀ noised afresh to the next timestep.

use super::config::SchedulerConfig;
use super::consistency::ConsistencySchedule;
use super::vp_prediction;
use crate::rng::TorchCpuRng;
use crate::Result;

pub(super) struct LcmStep {
    /// x₀ is clamped to ±this (`clip_sample`).
    clip: Option<f32>,
    timestep_scaling: f32,
}

/// LCM's σ_data.
const SIGMA_DATA: f32 = 0.5;

impl LcmStep {
    pub(super) fn new(config: &SchedulerConfig) -> Result<LcmStep> {
        let clip = config
            .flag("clip_sample", false)?
            .then(|| config.number("clip_sample_range", 1.0))
            .transpose()?
            .map(|r| r as f32);
        let timestep_scaling = config.number("timestep_scaling", 10.0)? as f32;
        Ok(LcmStep { clip, timestep_scaling })
    }

    /// `get_scalings_for_boundary_condition_discrete`: (c_skip, c_out) at training timestep `t`.
    fn scalings(&self, t: usize) -> (f32, f32) {
        let scaled = t as f32 * self.timestep_scaling;
        let d2 = SIGMA_DATA * SIGMA_DATA;
        let denominator = scaled * scaled + d2;
        (d2 / denominator, scaled / denominator.sqrt())
    }

    pub(super) fn step(&self, s: &ConsistencySchedule, step: usize, out: &[f32], x: &mut [f32], rng: &mut TorchCpuRng) {
        let alpha = s.alpha(step);
        let (sqrt_alpha, sqrt_beta) = (alpha.sqrt(), (1.0 - alpha).sqrt());
        let (c_skip, c_out) = self.scalings(s.timesteps[step]);
        let denoised: Vec<f32> = x
            .iter()
            .zip(out)
            .map(|(&x, &o)| {
                let x0 = vp_prediction(s.prediction, sqrt_alpha, sqrt_beta, x, o).0;
                let x0 = self.clip.map_or(x0, |r| x0.clamp(-r, r));
                c_out * x0 + c_skip * x
            })
            .collect();
        if s.is_last(step) {
            x.copy_from_slice(&denoised);
            return;
        }
        let alpha_prev = s.alpha(step + 1);
        let (a, b) = (alpha_prev.sqrt(), (1.0 - alpha_prev).sqrt());
        for ((x, d), n) in x.iter_mut().zip(denoised).zip(rng.randn(out.len())) {
            *x = a * d + b * n;
        }
    }
}
