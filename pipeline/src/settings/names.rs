//! The names settings are recorded under, in `dataset.json` and the PNG text.

use crate::settings::sampling::Sampling;
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
    if sampling.karras {
        "karras"
    } else {
        "default"
    }
}
