//! Every `vkdiff gen` setting as data, shared by `gen` and `dataset`, and the text chunks that
//! record them in the PNG: `parameters` in the A1111 form that image browsers and ComfyUI import,
//! plus every flag under its own key. The same settings give the same chunks, so a dataset image
//! and `vkdiff gen` run with its recorded settings write the same file.
//!
//! No chunk is named `prompt` or `workflow`: ComfyUI reads those as its graph JSON and refuses
//! the file when they are not, before it looks at `parameters`.

use crate::error::{Error, Result};
use crate::images::{load_control_image, read_image};
use crate::schedulers::SamplerKind;
use crate::settings::models::{flagged, recorded_path, ModelSettings};
use crate::settings::names::{control_depth_name, precision_name, schedule_name, schedule_records, RNG};
use crate::settings::prompt_syntax::PromptSyntax;
use crate::settings::sampling::{SizeConditioning, TextToImage};
use crate::RgbImage;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use vkdiff_render::control::ControlKind;
use vkdiff_setting::Message;

/// A value as A1111 writes it: in quotes where a comma or colon would split it.
fn quoted(value: &str) -> String {
    if value.contains([',', ':', '"']) {
        format!("\"{}\"", value.replace('"', "'"))
    } else {
        value.to_string()
    }
}

/// One `vkdiff gen` run: the models, the image's settings and its input files.
#[derive(Clone, Debug)]
pub struct GenSettings {
    pub models: ModelSettings,
    pub job: TextToImage,
    /// The depth control's input (depth EXR or image), as given.
    pub depth: Option<PathBuf>,
    /// The other controls' images, as given (`--control-image KIND=FILE`).
    pub control_images: Vec<(ControlKind, PathBuf)>,
    /// The IP-Adapter's style images, as given.
    pub ip_images: Vec<PathBuf>,
    /// img2img's init image, as given.
    pub init_image: Option<PathBuf>,
}

/// A1111's name of a sampler, as its `parameters` text and ComfyUI's importer spell it.
fn a1111_sampler(kind: SamplerKind) -> &'static str {
    match kind {
        SamplerKind::Euler => "Euler",
        SamplerKind::EulerAncestral => "Euler a",
        SamplerKind::DpmSolver2M => "DPM++ 2M",
        SamplerKind::Ddim => "DDIM",
        SamplerKind::Lcm => "LCM",
        SamplerKind::Tcd => "TCD",
    }
}

/// A model's name as A1111 gives it: the file name without its extension, or the folder name
/// (diffusers folders such as `stable-diffusion-xl-base-1.0` keep their dots).
fn model_name(path: &Path) -> String {
    let recorded = recorded_path(path);
    let path = Path::new(&recorded);
    let is_file = path
        .extension()
        .is_some_and(|e| ["safetensors", "ckpt", "pt", "bin"].iter().any(|x| e.eq_ignore_ascii_case(x)));
    let name = if is_file { path.file_stem() } else { path.file_name() };
    // A Hugging Face repository's name, without its `@COMMIT`.
    let name = name.map_or_else(|| recorded.clone(), |n| n.to_string_lossy().into_owned());
    name.split('@').next().unwrap_or_default().to_string()
}

fn join_paths(paths: &[PathBuf], separator: &str) -> String {
    paths.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(separator)
}

impl GenSettings {
    /// The PNG text chunks (and `--latents-out` metadata) of this run.
    pub fn png_text(&self) -> BTreeMap<String, String> {
        let (job, s, m) = (&self.job, &self.job.sampling, &self.models);
        let mut text = BTreeMap::from([
            ("parameters".to_string(), self.a1111_parameters()),
            ("positive_prompt".into(), job.prompt.clone()),
            ("seed".into(), job.seed.to_string()),
            ("steps".into(), s.steps.to_string()),
            ("cfg".into(), s.guidance_scale.to_string()),
            ("sampler".into(), s.sampler.to_string()),
            ("scheduler".into(), schedule_name(s).into()),
            ("width".into(), s.width.to_string()),
            ("height".into(), s.height.to_string()),
            ("precision".into(), precision_name(m.precision).into()),
            ("rng".into(), RNG.into()),
            ("model".into(), recorded_path(&m.model)),
            ("software".into(), format!("vkdiff {}", vkdiff_setting::version())),
        ]);
        let as_text = |v: serde_json::Value| v.as_str().map_or_else(|| v.to_string(), String::from);
        text.extend(schedule_records(s).into_iter().map(|(k, v)| (k.replace('-', "_"), as_text(v))));
        if let Some(n) = &job.negative_prompt {
            text.insert("negative_prompt".into(), n.clone());
        }
        if s.prompt_syntax == PromptSyntax::Weighted {
            text.insert("prompt_syntax".into(), "weighted".into());
        }
        if let (Some(init), Some(strength)) = (&self.init_image, s.strength) {
            text.insert("init_image".into(), init.display().to_string());
            text.insert("strength".into(), strength.to_string());
        }
        let c = &s.size_conditioning;
        if *c != SizeConditioning::default() {
            let size = |s: Option<(usize, usize)>| s.map_or("image size".into(), |(w, h)| format!("{w}x{h}"));
            text.insert("original_size".into(), size(c.original));
            text.insert("crops_coords_top_left".into(), format!("{},{}", c.crop_top_left.0, c.crop_top_left.1));
            text.insert("target_size".into(), size(c.target));
        }
        self.control_text(&mut text);
        if let Some(ip) = &m.ip_adapter {
            text.insert("ip_adapter".into(), recorded_path(&ip.adapter));
            text.insert("image_encoder".into(), recorded_path(&ip.encoder));
            text.insert("ip_images".into(), join_paths(&self.ip_images, "\n"));
            text.insert("ip_scale".into(), ip.scale.to_string());
        }
        if !m.loras.is_empty() {
            text.insert("loras".into(), m.lora_flags().join("\n"));
        }
        if let Some(vae) = &m.vae {
            text.insert("vae".into(), recorded_path(vae));
        }
        if let Some(unet) = &m.unet {
            text.insert("unet".into(), recorded_path(unet));
        }
        text
    }

    /// A1111's `parameters`: the prompt with its LoRAs as `<lora:NAME:STRENGTH>` tags, a
    /// `Negative prompt:` line (ComfyUI imports nothing without one), then `Key: value` pairs
    /// with A1111's sampler names ("DPM++ 2M Karras").
    fn a1111_parameters(&self) -> String {
        let (job, s, m) = (&self.job, &self.job.sampling, &self.models);
        let loras: String = m.loras.iter().map(|l| format!(" <lora:{}:{}>", model_name(&l.path), l.strength)).collect();
        let schedule = if s.schedule.karras { " Karras" } else { "" };
        let mut pairs = vec![
            format!("Steps: {}", s.steps),
            format!("Sampler: {}{schedule}", a1111_sampler(s.sampler)),
            format!("CFG scale: {}", s.guidance_scale),
            format!("Seed: {}", job.seed),
            format!("Size: {}x{}", s.width, s.height),
            format!("Model: {}", quoted(&model_name(&m.model))),
            format!("RNG: {RNG}"),
            format!("Precision: {}", precision_name(m.precision).to_uppercase()),
        ];
        if let Some(vae) = &m.vae {
            pairs.push(format!("VAE: {}", quoted(&model_name(vae))));
        }
        if let Some(unet) = &m.unet {
            pairs.push(format!("UNet: {}", quoted(&model_name(unet))));
        }
        if let Some(strength) = s.strength {
            pairs.push(format!("Denoising strength: {strength}"));
        }
        match &m.controlnets[..] {
            [c] if c.is_depth_only() => pairs.push(format!(
                "ControlNet: {}, Control scale: {}, Control range: {}-{}",
                quoted(&model_name(&c.model)),
                c.scale,
                c.start,
                c.end
            )),
            // As A1111's ControlNet extension lists its units.
            nets => pairs.extend(nets.iter().enumerate().map(|(k, c)| {
                format!(
                    "ControlNet {k}: \"Module: {}, Model: {}, Weight: {}, Guidance Start: {}, Guidance End: {}\"",
                    c.controls_name(),
                    model_name(&c.model).replace('"', "'"),
                    c.scale,
                    c.start,
                    c.end
                )
            })),
        }
        if let Some(ip) = &m.ip_adapter {
            pairs.push(format!(
                "IP-Adapter: {}, IP images: {}, IP scale: {}",
                quoted(&model_name(&ip.adapter)),
                self.ip_images.len(),
                ip.scale
            ));
        }
        let negative = job.negative_prompt.as_deref().unwrap_or("");
        format!("{}{loras}\nNegative prompt: {negative}\n{}", job.prompt, pairs.join(", "))
    }
}

/// The images one generation's guides read: the ControlNets' and the style images.
#[derive(Default)]
pub struct GuideInputs {
    /// Each control the ControlNets see, by kind.
    pub controls: BTreeMap<ControlKind, RgbImage>,
    pub style: Vec<RgbImage>,
    /// img2img's init image.
    pub init: Option<RgbImage>,
}

impl GenSettings {
    /// Reads the input images the settings name (before any model loads, so a bad file fails fast).
    pub fn read_inputs(&self) -> Result<GuideInputs> {
        let controls = self.read_controls()?;
        let style = if self.models.ip_adapter.is_some() {
            if self.ip_images.is_empty() {
                return Err(Error::Setting(
                    Message::setting("ip_adapter").then(" needs at least one ").and("ip_image"),
                ));
            }
            read_images(&self.ip_images)?
        } else {
            Vec::new()
        };
        let init = self.init_image.as_ref().map(|p| flagged("init_image", p, read_image(p))).transpose()?;
        Ok(GuideInputs { controls, style, init })
    }

    /// The image of every control the ControlNets see: the depth from `--depth`, the others
    /// from `--control-image`; an image no ControlNet sees is refused too.
    fn read_controls(&self) -> Result<BTreeMap<ControlKind, RgbImage>> {
        let wanted = self.models.control_kinds();
        if let Some((kind, _)) = self.control_images.iter().find(|(k, _)| !wanted.contains(k)) {
            return Err(Error::Setting(
                Message::setting("control_image")
                    .then(format!(" {}=: no ", kind.name()))
                    .and("controlnet")
                    .then(format!(" sees {} (add control={} to one)", kind.name(), kind.name())),
            ));
        }
        let mut controls = BTreeMap::new();
        for kind in wanted {
            let image = match (kind, &self.depth) {
                (ControlKind::Depth, Some(depth)) => {
                    let mode = self.models.controlnets[0].depth_mode;
                    flagged("depth", depth, load_control_image(depth, mode))?
                }
                (ControlKind::Depth, None) => {
                    return Err(Error::Setting(Message::setting("controlnet").then(" needs ").and("depth")))
                }
                _ => match self.control_images.iter().find(|(k, _)| *k == kind) {
                    Some((_, path)) => flagged("control_image", path, read_image(path))?,
                    None => {
                        return Err(Error::Setting(
                            Message::setting("controlnet")
                                .then(format!(" control={} needs ", kind.name()))
                                .and("control_image")
                                .then(format!(" {}=FILE", kind.name())),
                        ))
                    }
                },
            };
            controls.insert(kind, image);
        }
        Ok(controls)
    }

    /// The ControlNets' records: the paper's one depth ControlNet under the keys it always had;
    /// otherwise each as the `--controlnet` value that gives it back, one a line.
    fn control_text(&self, text: &mut BTreeMap<String, String>) {
        let nets = &self.models.controlnets;
        let depth = || self.depth.as_deref().map(|d| d.display().to_string()).unwrap_or_default();
        match &nets[..] {
            [] => {}
            [c] if c.is_depth_only() => {
                text.insert("controlnet".into(), recorded_path(&c.model));
                text.insert("depth".into(), depth());
                text.insert("control_depth".into(), control_depth_name(c.depth_mode).into());
                text.insert("control_scale".into(), c.scale.to_string());
                text.insert("control_start".into(), c.start.to_string());
                text.insert("control_end".into(), c.end.to_string());
            }
            nets => {
                text.insert("controlnets".into(), nets.iter().map(|c| c.flag()).collect::<Vec<_>>().join("\n"));
                if self.models.control_kinds().contains(&ControlKind::Depth) {
                    text.insert("depth".into(), depth());
                    text.insert("control_depth".into(), control_depth_name(nets[0].depth_mode).into());
                }
                if !self.control_images.is_empty() {
                    let images = self.control_images.iter().map(|(k, p)| format!("{}={}", k.name(), p.display()));
                    text.insert("control_images".into(), images.collect::<Vec<_>>().join("\n"));
                }
            }
        }
    }
}

/// Style images, each error naming its `ip_image`.
pub fn read_images(paths: &[std::path::PathBuf]) -> Result<Vec<RgbImage>> {
    paths.iter().map(|p| flagged("ip_image", p, read_image(p))).collect()
}
