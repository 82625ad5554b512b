//! Every `vkdiff gen` setting as data, shared by `gen` and `dataset`, and the text chunks that
//! record them in the PNG: `parameters` in the A1111 form image browsers parse, plus every flag
//! under its own key. The same settings give the same chunks, so a dataset image and `vkdiff gen`
//! run with its recorded settings write the same file.

use crate::text_to_image::{Sampling, TextToImage};
use std::collections::BTreeMap;
use std::path::PathBuf;
use vkdiff_render::control::ControlDepth;
use vkdiff_runtime::Dtype;

/// The depth ControlNet and how it steers.
#[derive(Clone, Debug, PartialEq)]
pub struct ControlNetSettings {
    pub model: PathBuf,
    /// How a depth EXR maps to brightness.
    pub depth_mode: ControlDepth,
    pub scale: f32,
    pub start: f64,
    pub end: f64,
}

/// The IP-Adapter, its image encoder and its weight.
#[derive(Clone, Debug, PartialEq)]
pub struct IpAdapterSettings {
    pub adapter: PathBuf,
    pub encoder: PathBuf,
    pub scale: f32,
}

#[derive(Clone, Debug, PartialEq)]
pub struct LoraSetting {
    pub path: PathBuf,
    pub strength: f32,
}

/// What loads once per process: the model, its guides and the LoRAs merged into it.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelSettings {
    pub model: PathBuf,
    pub precision: Dtype,
    pub controlnet: Option<ControlNetSettings>,
    pub ip_adapter: Option<IpAdapterSettings>,
    pub loras: Vec<LoraSetting>,
}

/// One `vkdiff gen` run: the models, the image's settings and its input files.
#[derive(Clone, Debug)]
pub struct GenSettings {
    pub models: ModelSettings,
    pub job: TextToImage,
    /// The ControlNet's input (depth EXR or image), as given.
    pub depth: Option<PathBuf>,
    /// The IP-Adapter's style images, as given.
    pub ip_images: Vec<PathBuf>,
}

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

fn join_paths(paths: &[PathBuf], separator: &str) -> String {
    paths.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(separator)
}

impl ModelSettings {
    /// The LoRAs as `--lora` takes them, FILE:STRENGTH.
    pub fn lora_flags(&self) -> Vec<String> {
        self.loras.iter().map(|l| format!("{}:{}", l.path.display(), l.strength)).collect()
    }

    fn lora_list(&self, separator: &str) -> String {
        self.lora_flags().join(separator)
    }
}

impl GenSettings {
    /// The PNG text chunks (and `--latents-out` metadata) of this run.
    pub fn png_text(&self) -> BTreeMap<String, String> {
        let (job, s, m) = (&self.job, &self.job.sampling, &self.models);
        let negative = job.negative_prompt.as_deref().map(|n| format!("\nNegative prompt: {n}")).unwrap_or_default();
        let schedule = if s.karras { " Karras" } else { "" };
        let parameters = format!(
            "{}{negative}\nSteps: {}, Sampler: {}{schedule}, CFG scale: {}, Seed: {}, Size: {}x{}, Model: {}, RNG: {RNG}, Precision: {}{}",
            job.prompt,
            s.steps,
            s.sampler,
            s.guidance_scale,
            job.seed,
            s.width,
            s.height,
            m.model.display(),
            precision_name(m.precision).to_uppercase(),
            self.guide_summary()
        );
        let mut text = BTreeMap::from([
            ("parameters".to_string(), parameters),
            ("prompt".into(), job.prompt.clone()),
            ("seed".into(), job.seed.to_string()),
            ("steps".into(), s.steps.to_string()),
            ("cfg".into(), s.guidance_scale.to_string()),
            ("sampler".into(), s.sampler.to_string()),
            ("scheduler".into(), schedule_name(s).into()),
            ("width".into(), s.width.to_string()),
            ("height".into(), s.height.to_string()),
            ("precision".into(), precision_name(m.precision).into()),
            ("rng".into(), RNG.into()),
            ("model".into(), m.model.display().to_string()),
            ("software".into(), format!("vkdiff {}", env!("CARGO_PKG_VERSION"))),
        ]);
        if let Some(n) = &job.negative_prompt {
            text.insert("negative_prompt".into(), n.clone());
        }
        if let Some(c) = &m.controlnet {
            text.insert("controlnet".into(), c.model.display().to_string());
            text.insert("depth".into(), self.depth.as_deref().map(|d| d.display().to_string()).unwrap_or_default());
            text.insert("control_depth".into(), control_depth_name(c.depth_mode).into());
            text.insert("control_scale".into(), c.scale.to_string());
            text.insert("control_start".into(), c.start.to_string());
            text.insert("control_end".into(), c.end.to_string());
        }
        if let Some(ip) = &m.ip_adapter {
            text.insert("ip_adapter".into(), ip.adapter.display().to_string());
            text.insert("image_encoder".into(), ip.encoder.display().to_string());
            text.insert("ip_images".into(), join_paths(&self.ip_images, "\n"));
            text.insert("ip_scale".into(), ip.scale.to_string());
        }
        if !m.loras.is_empty() {
            text.insert("loras".into(), m.lora_list("\n"));
        }
        text
    }

    /// The A1111-style summary of the guides, appended to `parameters`.
    fn guide_summary(&self) -> String {
        let m = &self.models;
        let mut parts = Vec::new();
        if let Some(c) = &m.controlnet {
            parts.push(format!("ControlNet: {}, Control scale: {}, Control range: {}-{}", c.model.display(), c.scale, c.start, c.end));
        }
        if let Some(ip) = &m.ip_adapter {
            parts.push(format!("IP-Adapter: {}, IP images: {}, IP scale: {}", ip.adapter.display(), self.ip_images.len(), ip.scale));
        }
        if !m.loras.is_empty() {
            parts.push(format!("LoRAs: {}", m.lora_list(" ")));
        }
        parts.iter().map(|p| format!(", {p}")).collect()
    }
}
