//! diffusers' `scheduler_config.json` and the training noise schedule it implies.
//!
//! `XScheduler.from_config(config)` takes the keys its class knows and its own defaults for the rest,
//! so the config keeps every key and each sampler asks for the ones its class reads, with that
//! class's default. A key a sampler does not implement is refused only when set to a value that
//! would change the result.

use crate::{Error, Result};
use serde_json::{Map, Value};
use std::path::Path;
use vkdiff_formats::Error as FileError;

/// stabilityai/stable-diffusion-xl-base-1.0 `scheduler/scheduler_config.json`.
/// SDXL base's `scheduler_config.json`.
pub const SDXL_SCHEDULER_CONFIG: &str = r#"{
  "_class_name": "EulerDiscreteScheduler",
  "_diffusers_version": "0.19.0.dev0",
  "beta_end": 0.012,
  "beta_schedule": "scaled_linear",
  "beta_start": 0.00085,
  "clip_sample": false,
  "interpolation_type": "linear",
  "num_train_timesteps": 1000,
  "prediction_type": "epsilon",
  "sample_max_value": 1.0,
  "set_alpha_to_one": false,
  "skip_prk_steps": true,
  "steps_offset": 1,
  "timestep_spacing": "leading",
  "trained_betas": null,
  "use_karras_sigmas": false
}"#;

/// A diffusers scheduler config (the SDXL model's is an `EulerDiscreteScheduler` one).
#[derive(Clone, Debug)]
pub struct SchedulerConfig {
    /// Where the config came from, for error messages.
    source: String,
    keys: Map<String, Value>,
}

/// What the network predicts (`prediction_type`): the noise, the velocity, or the clean sample
/// (SDXL-Lightning's one-step UNet).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PredictionType {
    Epsilon,
    V,
    Sample,
}

const PREDICTIONS: [(&str, PredictionType); 3] =
    [("epsilon", PredictionType::Epsilon), ("v_prediction", PredictionType::V), ("sample", PredictionType::Sample)];

/// How inference timesteps are spread over the training ones (`timestep_spacing`; Table 2 of
/// arXiv 2305.08891).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TimestepSpacing {
    Leading,
    Trailing,
    Linspace,
}

const SPACINGS: [(&str, TimestepSpacing); 3] = [
    ("leading", TimestepSpacing::Leading),
    ("trailing", TimestepSpacing::Trailing),
    ("linspace", TimestepSpacing::Linspace),
];

/// `name` among `table`'s (the names of a setting's values), or an error listing them.
pub(super) fn named<T: Copy>(table: &[(&str, T)], what: &str, name: &str) -> Result<T> {
    table.iter().find(|(n, _)| *n == name).map(|&(_, v)| v).ok_or_else(|| {
        let valid: Vec<&str> = table.iter().map(|(n, _)| *n).collect();
        Error::Config(format!("unknown {what} `{name}` (valid: {})", valid.join(", ")))
    })
}

/// `value`'s name in `table`.
pub(super) fn name_of<T: PartialEq>(table: &[(&'static str, T)], value: &T) -> &'static str {
    table.iter().find(|(_, v)| v == value).map_or("?", |(n, _)| n)
}

impl std::str::FromStr for TimestepSpacing {
    type Err = Error;
    fn from_str(name: &str) -> Result<TimestepSpacing> {
        named(&SPACINGS, "timestep spacing", name)
    }
}

impl std::fmt::Display for TimestepSpacing {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(name_of(&SPACINGS, self))
    }
}

impl std::str::FromStr for PredictionType {
    type Err = Error;
    fn from_str(name: &str) -> Result<PredictionType> {
        named(&PREDICTIONS, "prediction type", name)
    }
}

impl std::fmt::Display for PredictionType {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(name_of(&PREDICTIONS, self))
    }
}

impl SchedulerConfig {
    pub fn load(path: &Path) -> Result<SchedulerConfig> {
        let text =
            std::fs::read_to_string(path).map_err(|source| FileError::Io { path: path.to_path_buf(), source })?;
        let keys = parse(&text).map_err(|why| FileError::Format { path: path.to_path_buf(), why })?;
        Ok(SchedulerConfig { source: path.display().to_string(), keys })
    }

    /// A config given as JSON text.
    pub fn from_json(text: &str) -> Result<SchedulerConfig> {
        let keys = parse(text).map_err(|why| Error::Config(format!("scheduler config: {why}")))?;
        Ok(SchedulerConfig { source: "scheduler config".into(), keys })
    }

    /// The config SDXL base 1.0 ships with.
    pub fn sdxl_base() -> SchedulerConfig {
        SchedulerConfig {
            source: "SDXL base scheduler config".into(),
            keys: parse(SDXL_SCHEDULER_CONFIG).expect("built-in config is valid JSON"),
        }
    }

    /// ᾱ_t for every training timestep, as diffusers computes them: betas from a float32
    /// `torch.linspace`, then `torch.cumprod`, which accumulates in double and stores float32.
    pub(super) fn alphas_cumprod(&self) -> Result<Vec<f32>> {
        if self.value("trained_betas").is_some() {
            return Err(self.unsupported("trained_betas", "(only computed beta schedules are)"));
        }
        if self.flag("rescale_betas_zero_snr", false)? {
            return Err(self.unsupported("rescale_betas_zero_snr", ""));
        }
        let n = self.train_timesteps()?;
        let (start, end) = (self.number("beta_start", 0.0001)?, self.number("beta_end", 0.02)?);
        let betas: Vec<f32> = match self.text("beta_schedule", "linear")? {
            "linear" => torch_linspace(start as f32, end as f32, n),
            "scaled_linear" => {
                torch_linspace(start.powf(0.5) as f32, end.powf(0.5) as f32, n).iter().map(|b| b * b).collect()
            }
            _ => return Err(self.unsupported("beta_schedule", "(use \"scaled_linear\" or \"linear\")")),
        };
        let mut product = 1.0f64;
        Ok(betas
            .iter()
            .map(|beta| {
                product *= f64::from(1.0 - beta);
                product as f32
            })
            .collect())
    }

    pub(super) fn train_timesteps(&self) -> Result<usize> {
        match self.integer("num_train_timesteps", 1000)? {
            n @ 2.. => Ok(n as usize),
            _ => Err(self.unsupported("num_train_timesteps", "(at least 2)")),
        }
    }

    pub(super) fn steps_offset(&self) -> Result<u64> {
        self.integer("steps_offset", 0)
    }

    pub(crate) fn spacing(&self, default: &str) -> Result<TimestepSpacing> {
        self.text("timestep_spacing", default)?
            .parse()
            .map_err(|_| self.unsupported("timestep_spacing", "(use \"leading\", \"trailing\" or \"linspace\")"))
    }

    pub(crate) fn prediction(&self) -> Result<PredictionType> {
        self.text("prediction_type", "epsilon")?
            .parse()
            .map_err(|_| self.unsupported("prediction_type", "(use \"epsilon\", \"v_prediction\" or \"sample\")"))
    }

    /// This config with `key` set, as diffusers' `from_config(config, key=value)`: a flag given in
    /// place of the model's setting.
    pub fn with(&self, key: &str, value: &str) -> SchedulerConfig {
        let mut keys = self.keys.clone();
        keys.insert(key.into(), Value::String(value.into()));
        SchedulerConfig { source: format!("{} with {key} \"{value}\"", self.source), keys }
    }

    /// The config of the model at `path`: a diffusers folder's `scheduler/scheduler_config.json`,
    /// else SDXL base's (a single file carries none).
    pub fn of_model(path: &Path) -> Result<SchedulerConfig> {
        match Some(path.join("scheduler/scheduler_config.json")).filter(|p| path.is_dir() && p.is_file()) {
            Some(p) => SchedulerConfig::load(&p),
            None => Ok(SchedulerConfig::sdxl_base()),
        }
    }

    /// Whether the last σ is the smallest training σ rather than 0 (`final_sigmas_type`).
    pub(super) fn final_sigma_is_min(&self) -> Result<bool> {
        match self.text("final_sigmas_type", "zero")? {
            "zero" => Ok(false),
            "sigma_min" => Ok(true),
            _ => Err(self.unsupported("final_sigmas_type", "(use \"zero\" or \"sigma_min\")")),
        }
    }

    /// `sigma_min` / `sigma_max` overriding the ends of a Karras schedule.
    pub(super) fn karras_range(&self) -> Result<(Option<f64>, Option<f64>)> {
        let get = |key| self.value(key).map(|v| v.as_f64().ok_or_else(|| self.wrong_type(key, "a number"))).transpose();
        Ok((get("sigma_min")?, get("sigma_max")?))
    }

    /// A key set to a non-null value, if any; null means the class default, as in diffusers.
    pub(super) fn value(&self, key: &str) -> Option<&Value> {
        self.keys.get(key).filter(|v| !v.is_null())
    }

    pub(super) fn number(&self, key: &str, default: f64) -> Result<f64> {
        self.value(key).map_or(Ok(default), |v| v.as_f64().ok_or_else(|| self.wrong_type(key, "a number")))
    }

    pub(super) fn integer(&self, key: &str, default: u64) -> Result<u64> {
        self.value(key)
            .map_or(Ok(default), |v| v.as_u64().ok_or_else(|| self.wrong_type(key, "a non-negative integer")))
    }

    pub(super) fn flag(&self, key: &str, default: bool) -> Result<bool> {
        self.value(key).map_or(Ok(default), |v| v.as_bool().ok_or_else(|| self.wrong_type(key, "true or false")))
    }

    pub(super) fn text<'a>(&'a self, key: &str, default: &'a str) -> Result<&'a str> {
        self.value(key).map_or(Ok(default), |v| v.as_str().ok_or_else(|| self.wrong_type(key, "a string")))
    }

    /// Refuses `key` unless it is absent, null, or one of `allowed`.
    pub(super) fn only(&self, key: &str, allowed: &[Value]) -> Result<()> {
        match self.value(key) {
            Some(v) if !allowed.contains(v) => Err(self.unsupported(key, "by vkdiff")),
            _ => Ok(()),
        }
    }

    /// The one-line error for a key whose value vkdiff does not implement.
    pub(super) fn unsupported(&self, key: &str, hint: &str) -> Error {
        let value = self.value(key).map_or("null".into(), Value::to_string);
        Error::Config(format!("{}: {key} = {value} is not supported {hint}", self.source).trim_end().to_string())
    }

    fn wrong_type(&self, key: &str, what: &str) -> Error {
        Error::Config(format!("{}: {key} must be {what}, not {}", self.source, self.keys[key]))
    }
}

fn parse(text: &str) -> std::result::Result<Map<String, Value>, String> {
    // Python's json writes DPMSolverMultistepScheduler's default `lambda_min_clipped` as
    // `-Infinity`, which JSON lacks; null stands for that default.
    match serde_json::from_str(&text.replace(": -Infinity", ": null")) {
        Ok(Value::Object(keys)) => Ok(keys),
        Ok(_) => Err("not a JSON object".into()),
        Err(e) => Err(format!("not valid JSON: {e}")),
    }
}

/// `torch.linspace(start, end, n, dtype=float32)` on the CPU: the first half counts up from `start`,
/// the second down from `end`, and the compiled kernel fuses each `a + step·i` into one FMA.
fn torch_linspace(start: f32, end: f32, n: usize) -> Vec<f32> {
    let step = (end - start) / (n - 1) as f32;
    (0..n)
        .map(|i| if i < n / 2 { step.mul_add(i as f32, start) } else { (-step).mul_add((n - 1 - i) as f32, end) })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn python_minus_infinity_reads_as_the_default() {
        let config = SchedulerConfig::from_json(r#"{"lambda_min_clipped": -Infinity, "solver_order": 2}"#).unwrap();
        assert!(config.value("lambda_min_clipped").is_none());
    }

    #[test]
    fn missing_file_is_an_io_error_naming_it() {
        let err = SchedulerConfig::load(Path::new("/nonexistent/scheduler_config.json")).unwrap_err();
        assert!(
            matches!(err, Error::File(FileError::Io { .. }))
                && err.to_string().contains("/nonexistent/scheduler_config.json")
        );
    }
}
