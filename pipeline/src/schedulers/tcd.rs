//! diffusers' `TCDScheduler` step (Trajectory Consistency Distillation): the model's x₀ and ε
//! land on the intermediate timestep s = ⌊(1 − γ)·t_prev⌋, and, with γ > 0 and except at the
//! last step, that sample is noised forward from s to t_prev.

use super::consistency::ConsistencySchedule;
use super::vp_prediction;
use crate::rng::TorchCpuRng;

pub(super) struct TcdStep {
    /// γ, the share of each step taken stochastically.
    pub eta: f64,
}

impl TcdStep {
    pub(super) fn step(&self, s: &ConsistencySchedule, step: usize, out: &[f32], x: &mut [f32], rng: &mut TorchCpuRng) {
        let prev = s.timesteps.get(step + 1).copied().unwrap_or(0);
        // torch: a float32 (1 − γ) times the integer timestep, floored.
        let timestep_s = ((1.0 - self.eta) as f32 * prev as f32).floor() as usize;
        let alpha = s.alpha(step);
        let (alpha_prev, alpha_s) = (s.alphas_cumprod[prev], s.alphas_cumprod[timestep_s]);
        let (sqrt_alpha, sqrt_beta) = (alpha.sqrt(), (1.0 - alpha).sqrt());
        let (sqrt_alpha_s, sqrt_beta_s) = (alpha_s.sqrt(), (1.0 - alpha_s).sqrt());
        for (x, &o) in x.iter_mut().zip(out) {
            let (x0, eps) = vp_prediction(s.prediction, sqrt_alpha, sqrt_beta, *x, o);
            *x = sqrt_alpha_s * x0 + sqrt_beta_s * eps;
        }
        if self.eta > 0.0 && !s.is_last(step) {
            let ratio = alpha_prev / alpha_s;
            let (a, b) = (ratio.sqrt(), (1.0 - ratio).sqrt());
            for (x, n) in x.iter_mut().zip(rng.randn(out.len())) {
                *x = a * *x + b * n;
            }
        }
    }
}
