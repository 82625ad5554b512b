//! diffusers `DPMSolverMultistepScheduler` as DPM++ 2M: algorithm dpmsolver++, order 2, midpoint.
//! It works on the variance-preserving latent (no input scaling, unit initial noise) and steps in
//! λ = ln(α/σ_vp), first-order on the first step and, under `lower_order_final`, on the last.

use super::config::{PredictionType, SchedulerConfig, TimestepSpacing};
use super::{interp, karras_sigmas, log_sigmas, numpy_linspace, sigma_to_t, trailing_timesteps, train_sigmas, Solver};
use crate::rng::TorchCpuRng;
use crate::Result;
use serde_json::Value;

pub(super) struct DpmSolverMultistep {
    timesteps: Vec<f32>,
    sigmas: Vec<f32>,
    prediction: PredictionType,
    /// Whether the last step is first-order (`lower_order_final`, `euler_at_final`, a final σ of 0).
    first_order_final: bool,
    /// x₀ predicted at the previous step.
    previous: Option<Vec<f32>>,
}

impl DpmSolverMultistep {
    /// `custom`: `set_timesteps(timesteps=…)`'s schedule in place of the spaced one.
    pub(super) fn new(
        config: &SchedulerConfig,
        karras: bool,
        steps: usize,
        custom: Option<&[u32]>,
    ) -> Result<DpmSolverMultistep> {
        // "deis" and the other solver types are remapped by diffusers itself.
        config.only("algorithm_type", &["dpmsolver++".into(), "deis".into()])?;
        config.only("solver_type", &["midpoint".into(), "logrho".into(), "bh1".into(), "bh2".into()])?;
        config.only("solver_order", &[2.into()])?;
        config.only("lambda_min_clipped", &[])?;
        config.only("variance_type", &[])?;
        for key in ["thresholding", "use_lu_lambdas", "use_exponential_sigmas", "use_beta_sigmas", "use_flow_sigmas"] {
            config.only(key, &[Value::Bool(false)])?;
        }
        let prediction = config.prediction()?;
        let final_sigma_min = config.final_sigma_is_min()?;
        // Read even when Karras σ's replace the spaced timesteps, as diffusers does.
        let spacing = config.spacing("linspace")?;
        let train = train_sigmas(&config.alphas_cumprod()?);
        let (timesteps, sigmas): (Vec<f32>, Vec<f64>) = if karras {
            // The full training range (unless overridden), timesteps rounded to integers.
            let (sigma_min, sigma_max) = config.karras_range()?;
            let sigmas = karras_sigmas(
                sigma_min.unwrap_or(f64::from(train[0])),
                sigma_max.unwrap_or(f64::from(train[train.len() - 1])),
                steps,
            );
            let logs = log_sigmas(&train);
            (sigmas.iter().map(|&s| sigma_to_t(s, &logs).round_ties_even() as f32).collect(), sigmas)
        } else {
            let timesteps = match custom {
                Some(custom) => custom.iter().map(|&t| t as f32).collect(),
                None => dpm_timesteps(spacing, steps, train.len(), config.steps_offset()?),
            };
            let sigmas = timesteps.iter().map(|&t| interp(f64::from(t), &train)).collect();
            (timesteps, sigmas)
        };
        let last = if final_sigma_min { train[0] } else { 0.0 };
        let sigmas: Vec<f32> = sigmas.iter().map(|&s| s as f32).chain([last]).collect();
        let first_order_final = config.flag("euler_at_final", false)?
            || (config.flag("lower_order_final", true)? && timesteps.len() < 15)
            || !final_sigma_min;
        Ok(DpmSolverMultistep { timesteps, sigmas, prediction, first_order_final, previous: None })
    }
}

/// DPM-Solver's own spacings: leading and linspace split the range into `steps + 1` parts.
fn dpm_timesteps(spacing: TimestepSpacing, steps: usize, train: usize, offset: u64) -> Vec<f32> {
    let timesteps: Vec<f64> = match spacing {
        TimestepSpacing::Leading => {
            let ratio = (train / (steps + 1)) as f64;
            (1..=steps).rev().map(|k| k as f64 * ratio + offset as f64).collect()
        }
        TimestepSpacing::Linspace => {
            numpy_linspace(0.0, (train - 1) as f64, steps + 1)[1..].iter().rev().map(|t| t.round_ties_even()).collect()
        }
        TimestepSpacing::Trailing => trailing_timesteps(train, steps),
    };
    timesteps.iter().map(|&t| t as f32).collect()
}

/// (α_t, σ_t) of the variance-preserving latent at noise level σ.
fn alpha_sigma(sigma: f32) -> (f32, f32) {
    let alpha = 1.0 / (sigma * sigma + 1.0).sqrt();
    (alpha, sigma * alpha)
}

impl Solver for DpmSolverMultistep {
    fn timesteps(&self) -> &[f32] {
        &self.timesteps
    }

    fn sigmas(&self) -> Option<&[f32]> {
        Some(&self.sigmas)
    }

    fn add_noise(&self, step: usize, x0: &[f32], noise: &[f32]) -> Vec<f32> {
        let (alpha, sigma) = alpha_sigma(self.sigmas[step]);
        x0.iter().zip(noise).map(|(x, n)| alpha * x + sigma * n).collect()
    }

    fn init_noise_sigma(&self) -> f32 {
        1.0
    }

    fn scale_model_input(&self, _step: usize, x: &[f32]) -> Vec<f32> {
        x.to_vec()
    }

    fn step(&mut self, step: usize, eps: &[f32], x: &mut [f32], _rng: &mut TorchCpuRng) {
        let (alpha_s0, sigma_s0) = alpha_sigma(self.sigmas[step]);
        let x0: Vec<f32> = match self.prediction {
            PredictionType::Epsilon => x.iter().zip(eps).map(|(x, e)| (x - sigma_s0 * e) / alpha_s0).collect(),
            PredictionType::V => x.iter().zip(eps).map(|(x, e)| alpha_s0 * x - sigma_s0 * e).collect(),
            PredictionType::Sample => eps.to_vec(),
        };
        let (alpha_t, sigma_t) = alpha_sigma(self.sigmas[step + 1]);
        // λ = +∞ at a final σ of 0, where the update reduces to x = x₀.
        let lambda_t = alpha_t.ln() - sigma_t.ln();
        let lambda_s0 = alpha_s0.ln() - sigma_s0.ln();
        let h = lambda_t - lambda_s0;
        let ratio = sigma_t / sigma_s0;
        let coef = alpha_t * ((-h).exp() - 1.0);
        let last = step + 1 == self.timesteps.len();
        match self.previous.as_deref() {
            Some(x0_prev) if !(last && self.first_order_final) => {
                let (alpha_s1, sigma_s1) = alpha_sigma(self.sigmas[step - 1]);
                let lambda_s1 = alpha_s1.ln() - sigma_s1.ln();
                let r0 = (lambda_s0 - lambda_s1) / h;
                let (inv_r0, half_coef) = (1.0 / r0, 0.5 * coef);
                for ((x, &m0), &m1) in x.iter_mut().zip(&x0).zip(x0_prev) {
                    *x = ratio * *x - coef * m0 - half_coef * (inv_r0 * (m0 - m1));
                }
            }
            _ => {
                for (x, &m0) in x.iter_mut().zip(&x0) {
                    *x = ratio * *x - coef * m0;
                }
            }
        }
        self.previous = Some(x0);
    }
}
