//! The names settings are recorded under, in `dataset.json` and the PNG text.

use crate::schedulers::{SamplerKind, TCD_DEFAULT_ETA};
use crate::settings::sampling::Sampling;
use serde_json::Value;
use vkdiff_render::control::ControlDepth;
use vkdiff_runtime::Dtype;

/// The noise generator's name (the only one: torch's CPU generator, bit for bit).
pub const RNG: &str = "torch-cpu";

pub fn precision_name(dtype: Dtype) -> &'static str {
    match dtype {
        Dtype::F16 => "f16",
        Dtype::F32 => "f32",
    }
}

pub fn control_depth_name(mode: ControlDepth) -> &'static str {
    match mode {
        ControlDepth::Inverse => "inverse",
        ControlDepth::Linear => "linear",
    }
}

pub fn schedule_name(sampling: &Sampling) -> &'static str {
    if sampling.schedule.karras {
        "karras"
    } else {
        "default"
    }
}

/// The schedule options a run set beside the sampler, under their flags' names, as text: the
/// spacing and prediction type given in place of the model's, custom timesteps, and TCD's γ
/// (always, since it shapes every TCD image).
pub fn schedule_records(sampling: &Sampling) -> Vec<(&'static str, Value)> {
    let o = &sampling.schedule;
    let mut records = Vec::new();
    if let Some(spacing) = o.spacing {
        records.push(("timestep-spacing", spacing.to_string().into()));
    }
    if let Some(prediction) = o.prediction {
        records.push(("prediction-type", prediction.to_string().into()));
    }
    if let Some(timesteps) = &o.timesteps {
        records.push(("timesteps", timesteps_text(timesteps).into()));
    }
    if sampling.sampler == SamplerKind::Tcd {
        records.push(("eta", o.eta.unwrap_or(TCD_DEFAULT_ETA).into()));
    }
    records
}

/// Timesteps as `--timesteps` takes them: `999,749,499,249`.
pub(crate) fn timesteps_text(timesteps: &[u32]) -> String {
    timesteps.iter().map(u32::to_string).collect::<Vec<_>>().join(",")
}
