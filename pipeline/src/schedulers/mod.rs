//! diffusers' schedulers, reproduced to float32 rounding: the timesteps the UNet sees, the noise
//! levels, and the update of the latent at each step.
//!
//! Each sampler follows its diffusers class op for op, in the precision diffusers computes in:
//! training schedules in float32 torch ops, inference σ's in float64 numpy then float32, and the
//! per-step update in float32 with the same operation order.

mod config;
mod consistency;
mod ddim;
mod dpmsolver_multistep;
mod euler_discrete;
mod lcm;
mod tcd;

pub use config::{PredictionType, SchedulerConfig, TimestepSpacing, SDXL_SCHEDULER_CONFIG};

use crate::rng::TorchCpuRng;
use crate::{Error, Result};
use consistency::{Consistency, ConsistencyStep};
use lcm::LcmStep;
use std::fmt;
use std::str::FromStr;
use tcd::TcdStep;

/// The samplers vkdiff offers, named `euler`, `euler_a`, `dpmpp_2m`, `ddim`, `lcm` and `tcd`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SamplerKind {
    Euler,
    EulerAncestral,
    DpmSolver2M,
    Ddim,
    Lcm,
    Tcd,
}

const NAMES: [(&str, SamplerKind); 6] = [
    ("euler", SamplerKind::Euler),
    ("euler_a", SamplerKind::EulerAncestral),
    ("dpmpp_2m", SamplerKind::DpmSolver2M),
    ("ddim", SamplerKind::Ddim),
    ("lcm", SamplerKind::Lcm),
    ("tcd", SamplerKind::Tcd),
];

impl FromStr for SamplerKind {
    type Err = Error;
    fn from_str(name: &str) -> Result<SamplerKind> {
        config::named(&NAMES, "sampler", name)
    }
}

impl fmt::Display for SamplerKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(config::name_of(&NAMES, self))
    }
}

impl SamplerKind {
    /// diffusers' class for this sampler.
    pub fn diffusers_class(self) -> &'static str {
        match self {
            SamplerKind::Euler => "EulerDiscreteScheduler",
            SamplerKind::EulerAncestral => "EulerAncestralDiscreteScheduler",
            SamplerKind::DpmSolver2M => "DPMSolverMultistepScheduler",
            SamplerKind::Ddim => "DDIMScheduler",
            SamplerKind::Lcm => "LCMScheduler",
            SamplerKind::Tcd => "TCDScheduler",
        }
    }

    /// Whether its diffusers class takes `set_timesteps(timesteps=…)`.
    fn takes_timesteps(self) -> bool {
        !matches!(self, SamplerKind::EulerAncestral | SamplerKind::Ddim)
    }

    /// Whether its schedule reads `timestep_spacing` (LCM and TCD pick from their distillation
    /// schedule instead).
    pub(crate) fn reads_spacing(self) -> bool {
        !matches!(self, SamplerKind::Lcm | SamplerKind::Tcd)
    }
}

/// TCD's γ when none is given (`TCDScheduler.step`'s default).
pub const TCD_DEFAULT_ETA: f64 = 0.3;

/// What a run sets beside the sampler and its step count: diffusers' `from_config(config, …)`
/// overrides, `use_karras_sigmas`, `set_timesteps(timesteps=…)` and `step(eta=…)`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ScheduleOptions {
    /// Karras et al.'s noise levels (euler, dpmpp_2m).
    pub karras: bool,
    /// `timestep_spacing` in place of the model config's.
    pub spacing: Option<TimestepSpacing>,
    /// `prediction_type` in place of the model config's.
    pub prediction: Option<PredictionType>,
    /// The schedule itself, strictly descending training timesteps; the step count is its length.
    pub timesteps: Option<Vec<u32>>,
    /// TCD's γ, in [0, 1] (None: [`TCD_DEFAULT_ETA`]).
    pub eta: Option<f64>,
}

/// What each diffusers scheduler class provides.
trait Solver {
    fn timesteps(&self) -> &[f32];
    fn sigmas(&self) -> Option<&[f32]>;
    fn init_noise_sigma(&self) -> f32;
    fn scale_model_input(&self, step: usize, x: &[f32]) -> Vec<f32>;
    /// `scheduler.add_noise(x0, noise, timesteps[step])` with the begin index at `step`.
    fn add_noise(&self, step: usize, x0: &[f32], noise: &[f32]) -> Vec<f32>;
    fn step(&mut self, step: usize, eps: &[f32], x: &mut [f32], rng: &mut TorchCpuRng);
}

/// A configured scheduler with its timesteps set.
pub struct Sampler {
    solver: Box<dyn Solver>,
}

impl Sampler {
    /// What diffusers gives for `XScheduler.from_config(config, use_karras_sigmas=karras, …overrides)`
    /// then `set_timesteps(steps)` (or `set_timesteps(timesteps=…)`), X = EulerDiscreteScheduler /
    /// EulerAncestralDiscreteScheduler / DPMSolverMultistepScheduler (dpmsolver++, order 2,
    /// midpoint, lower_order_final) / DDIMScheduler / LCMScheduler / TCDScheduler.
    /// Like diffusers, trailing spacing can yield one timestep more than `steps` (61 steps → 62).
    pub fn new(
        kind: SamplerKind,
        config: &SchedulerConfig,
        steps: usize,
        options: &ScheduleOptions,
    ) -> Result<Sampler> {
        let config = &options_config(kind, config, options)?;
        let custom = options.timesteps.as_deref();
        let steps = custom.map_or(steps, <[u32]>::len);
        if steps == 0 {
            return Err(Error::Config(format!("{kind} needs at least 1 step")));
        }
        if let Some(timesteps) = custom {
            check_custom_timesteps(kind, config, timesteps, options.karras)?;
        }
        if options.karras && !matches!(kind, SamplerKind::Euler | SamplerKind::DpmSolver2M) {
            // diffusers' DDIM, LCM and TCD have no Karras option, and its Euler-ancestral silently ignores it.
            return Err(Error::Config(format!("Karras sigmas are not available with {kind} (use euler or dpmpp_2m)")));
        }
        match options.eta {
            Some(eta) if kind != SamplerKind::Tcd => {
                return Err(Error::Config(format!("eta {eta} is TCD's gamma; {kind} takes none (use --sampler tcd)")))
            }
            Some(eta) if !(0.0..=1.0).contains(&eta) => {
                return Err(Error::Config(format!("tcd: eta (gamma) {eta} must lie in [0, 1]")))
            }
            _ => {}
        }
        let karras = options.karras;
        let solver: Box<dyn Solver> = match kind {
            SamplerKind::Euler => Box::new(euler_discrete::EulerDiscrete::new(config, karras, steps, custom)?),
            SamplerKind::EulerAncestral => Box::new(euler_discrete::EulerDiscrete::ancestral(config, steps)?),
            SamplerKind::DpmSolver2M => {
                Box::new(dpmsolver_multistep::DpmSolverMultistep::new(config, karras, steps, custom)?)
            }
            SamplerKind::Ddim => Box::new(ddim::Ddim::new(config, steps)?),
            SamplerKind::Lcm => {
                Box::new(Consistency::new(config, steps, custom, ConsistencyStep::Lcm(LcmStep::new(config)?))?)
            }
            SamplerKind::Tcd => {
                let eta = options.eta.unwrap_or(TCD_DEFAULT_ETA);
                Box::new(Consistency::new(config, steps, custom, ConsistencyStep::Tcd(TcdStep { eta }))?)
            }
        };
        // diffusers starts at the second occurrence of a repeated first timestep and then runs
        // past the end of its schedule.
        if let [first, second, ..] = solver.timesteps() {
            if first == second {
                return Err(Error::Config(format!(
                    "{steps} steps are too many for {kind}: its first timestep {first} repeats"
                )));
            }
        }
        Ok(Sampler { solver })
    }
    /// The value the UNet receives at each step (diffusers' timesteps, as float32).
    pub fn timesteps(&self) -> &[f32] {
        self.solver.timesteps()
    }

    /// The noise levels, one more than the timesteps, for the samplers that have them.
    pub fn sigmas(&self) -> Option<&[f32]> {
        self.solver.sigmas()
    }

    /// What the initial unit-variance noise is multiplied by.
    pub fn init_noise_sigma(&self) -> f32 {
        self.solver.init_noise_sigma()
    }

    /// The UNet's input for latent `x` at `step`.
    pub fn scale_model_input(&self, step: usize, x: &[f32]) -> Vec<f32> {
        self.solver.scale_model_input(step, x)
    }

    /// img2img's start: `x0` noised to the level of timestep `step`, as diffusers'
    /// `add_noise` after `set_begin_index(step)`.
    pub fn add_noise(&self, step: usize, x0: &[f32], noise: &[f32]) -> Vec<f32> {
        assert_eq!(x0.len(), noise.len(), "latent and noise sizes differ");
        self.solver.add_noise(step, x0, noise)
    }

    /// One `scheduler.step(eps, t, x, generator)`: `eps` is the (guidance-combined) model output,
    /// `x` the flat NCHW latent, updated in place; ancestral noise is drawn from `rng` as diffusers
    /// draws it (a randn of x's shape at every step, the last included). Steps go in order from 0:
    /// DPM-Solver keeps the previous step's prediction.
    pub fn step(&mut self, step: usize, eps: &[f32], x: &mut [f32], rng: &mut TorchCpuRng) {
        assert_eq!(eps.len(), x.len(), "model output and latent sizes differ");
        assert!(step < self.timesteps().len(), "step {step} is past the last of {} timesteps", self.timesteps().len());
        self.solver.step(step, eps, x, rng);
    }
}

/// The model's config with the run's overrides, refusing those the sampler's diffusers class
/// ignores or cannot run.
fn options_config(kind: SamplerKind, config: &SchedulerConfig, options: &ScheduleOptions) -> Result<SchedulerConfig> {
    let mut config = config.clone();
    if let Some(spacing) = options.spacing {
        if !kind.reads_spacing() {
            return Err(Error::Config(format!(
                "{kind} has no timestep spacing: {} picks its timesteps from its distillation schedule \
                    (original_inference_steps); give the timesteps themselves instead",
                kind.diffusers_class()
            )));
        }
        config = config.with("timestep_spacing", &spacing.to_string());
    }
    if let Some(prediction) = options.prediction {
        config = config.with("prediction_type", &prediction.to_string());
    }
    if kind == SamplerKind::EulerAncestral && config.prediction()? == PredictionType::Sample {
        // diffusers raises NotImplementedError there.
        return Err(config.unsupported("prediction_type", "with euler_a (use euler)"));
    }
    Ok(config)
}

/// diffusers' checks of `set_timesteps(timesteps=…)`: a class that takes them, no Karras σ's, strictly
/// descending training timesteps.
fn check_custom_timesteps(kind: SamplerKind, config: &SchedulerConfig, timesteps: &[u32], karras: bool) -> Result<()> {
    if !kind.takes_timesteps() {
        return Err(Error::Config(format!(
            "{kind} takes no custom timesteps ({} has none; use euler, dpmpp_2m, lcm or tcd)",
            kind.diffusers_class()
        )));
    }
    if karras {
        return Err(Error::Config("custom timesteps cannot be combined with Karras sigmas".into()));
    }
    if timesteps.windows(2).any(|w| w[1] >= w[0]) {
        return Err(Error::Config(format!("timesteps {timesteps:?} must be strictly descending")));
    }
    let train = config.train_timesteps()?;
    match timesteps.first() {
        Some(&first) if first as usize >= train => Err(Error::Config(format!(
            "timestep {first} is past the model's {train} training timesteps (0 to {})",
            train - 1
        ))),
        _ => Ok(()),
    }
}

/// Euler-family timesteps (`EulerDiscreteScheduler.set_timesteps`), in float64 before their cast.
fn spaced_timesteps(spacing: TimestepSpacing, steps: usize, train: usize, offset: u64) -> Vec<f64> {
    match spacing {
        TimestepSpacing::Leading => {
            let ratio = (train / steps) as f64;
            (0..steps).rev().map(|k| k as f64 * ratio + offset as f64).collect()
        }
        TimestepSpacing::Trailing => trailing_timesteps(train, steps),
        TimestepSpacing::Linspace => numpy_linspace(0.0, (train - 1) as f64, steps).into_iter().rev().collect(),
    }
}

/// `np.arange(train, 0, -train / steps).round() - 1`, with numpy's float arange: its length is
/// `ceil(train / step)` (one more than `steps` when that rounds up) and element i is
/// `start + i·((start + step) − start)`.
fn trailing_timesteps(train: usize, steps: usize) -> Vec<f64> {
    let start = train as f64;
    let step = -(start / steps as f64);
    let len = ((0.0 - start) / step).ceil() as usize;
    let delta = (start + step) - start;
    (0..len)
        .map(|i| match i {
            0 => start,
            1 => start + step,
            _ => start + i as f64 * delta,
        })
        .map(|t| t.round_ties_even() - 1.0)
        .collect()
}

/// `np.linspace(start, stop, num)`: `i·step + start`, the last point exactly `stop`.
fn numpy_linspace(start: f64, stop: f64, num: usize) -> Vec<f64> {
    let step = (stop - start) / num.saturating_sub(1) as f64;
    (0..num)
        .map(|i| {
            if i + 1 == num && num > 1 {
                stop
            } else if i == 0 {
                start
            } else {
                i as f64 * step + start
            }
        })
        .collect()
}

/// The Euler family's `add_noise`: x0 + noise · σ.
fn add_sigma_noise(sigma: f32, x0: &[f32], noise: &[f32]) -> Vec<f32> {
    x0.iter().zip(noise).map(|(x, n)| x + n * sigma).collect()
}

/// σ_t = √((1 − ᾱ_t)/ᾱ_t) for every training timestep, in float32 as torch computes it.
fn train_sigmas(alphas_cumprod: &[f32]) -> Vec<f32> {
    alphas_cumprod.iter().map(|a| ((1.0 - a) / a).sqrt()).collect()
}

/// `np.log` of float32 σ's, kept in float32.
fn log_sigmas(sigmas: &[f32]) -> Vec<f32> {
    sigmas.iter().map(|&s| f64::from(s).ln() as f32).collect()
}

/// `np.interp(t, arange(len), ys)`: linear in t, clamped at both ends.
fn interp(t: f64, ys: &[f32]) -> f64 {
    let last = ys.len() - 1;
    if t <= 0.0 {
        return f64::from(ys[0]);
    }
    let j = t.floor() as usize;
    if j >= last {
        return f64::from(ys[last]);
    }
    let (y0, y1) = (f64::from(ys[j]), f64::from(ys[j + 1]));
    (y1 - y0) * (t - j as f64) + y0
}

/// Karras et al. (2022) σ's with ρ = 7 from `sigma_max` down to `sigma_min`, in float64.
fn karras_sigmas(sigma_min: f64, sigma_max: f64, steps: usize) -> Vec<f64> {
    const RHO: f64 = 7.0;
    let (min_inv_rho, max_inv_rho) = (sigma_min.powf(1.0 / RHO), sigma_max.powf(1.0 / RHO));
    numpy_linspace(0.0, 1.0, steps)
        .iter()
        .map(|ramp| (max_inv_rho + ramp * (min_inv_rho - max_inv_rho)).powf(RHO))
        .collect()
}

/// The fractional training timestep of `sigma`: log-σ interpolation between its neighbours
/// (`_sigma_to_t`; the neighbour differences are float32 like diffusers' `log_sigmas`).
fn sigma_to_t(sigma: f64, log_sigmas: &[f32]) -> f64 {
    let log_sigma = sigma.max(1e-10).ln();
    let low = log_sigmas.iter().rposition(|&l| log_sigma - f64::from(l) >= 0.0).unwrap_or(0).min(log_sigmas.len() - 2);
    let (lo, hi) = (log_sigmas[low], log_sigmas[low + 1]);
    let w = ((f64::from(lo) - log_sigma) / f64::from(lo - hi)).clamp(0.0, 1.0);
    (1.0 - w) * low as f64 + w * (low + 1) as f64
}

/// x₀ predicted at noise level σ on a variance-exploding latent (Euler family).
fn denoised(prediction: PredictionType, sigma: f32, x: f32, eps: f32) -> f32 {
    match prediction {
        PredictionType::Epsilon => x - sigma * eps,
        PredictionType::Sample => eps,
        PredictionType::V => {
            let c_out = -sigma / (sigma * sigma + 1.0).sqrt();
            eps * c_out + x / (sigma * sigma + 1.0)
        }
    }
}

/// x₀ and ε from the model output `out` on the variance-preserving latent `x`, given √ᾱ and
/// √(1 − ᾱ), in the float32 operation order of diffusers' DDIM, LCM and TCD.
fn vp_prediction(prediction: PredictionType, sqrt_alpha: f32, sqrt_beta: f32, x: f32, out: f32) -> (f32, f32) {
    match prediction {
        PredictionType::Epsilon => ((x - sqrt_beta * out) / sqrt_alpha, out),
        PredictionType::V => (sqrt_alpha * x - sqrt_beta * out, sqrt_alpha * out + sqrt_beta * x),
        PredictionType::Sample => (out, (x - sqrt_alpha * out) / sqrt_beta),
    }
}

/// The variance-preserving `add_noise`: √ᾱ·x₀ + √(1 − ᾱ)·noise.
fn vp_add_noise(alpha_cumprod: f32, x0: &[f32], noise: &[f32]) -> Vec<f32> {
    let (a, b) = (alpha_cumprod.sqrt(), (1.0 - alpha_cumprod).sqrt());
    x0.iter().zip(noise).map(|(x, n)| a * x + b * n).collect()
}

/// `x / √(σ² + 1)`, the Euler family's model input.
fn scale_by_sigma(x: &[f32], sigma: f32) -> Vec<f32> {
    let scale = (sigma * sigma + 1.0).sqrt();
    x.iter().map(|v| v / scale).collect()
}

/// `init_noise_sigma` of the Euler family: σ_max, or √(σ_max² + 1) for leading spacing.
fn euler_init_noise_sigma(sigmas: &[f32], spacing: TimestepSpacing) -> f32 {
    let max = sigmas.iter().copied().fold(f32::MIN, f32::max);
    match spacing {
        TimestepSpacing::Leading => (max * max + 1.0).sqrt(),
        TimestepSpacing::Trailing | TimestepSpacing::Linspace => max,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sampler_names_round_trip() {
        for (name, kind) in NAMES {
            assert_eq!(name.parse::<SamplerKind>().unwrap(), kind);
            assert_eq!(kind.to_string(), name);
        }
    }

    #[test]
    fn numpy_arange_adds_a_trailing_timestep_for_some_step_counts() {
        let timesteps = trailing_timesteps(1000, 61);
        assert_eq!((timesteps.len(), timesteps[0], timesteps[1], timesteps[61]), (62, 999.0, 983.0, -1.0));
        assert_eq!(trailing_timesteps(1000, 30).len(), 30);
    }
}
