//! What loads once per process: the SDXL model, its ControlNets, its IP-Adapter and the LoRAs
//! merged into it; checked before anything loads.

use crate::error::{Error, Result};
use crate::sdxl::Swaps;
use crate::settings::ip_scale::IpScale;
use crate::settings::VaeTilingSetting;
use std::path::{Path, PathBuf};
use vkdiff_formats::SafeTensors;
use vkdiff_lora::LoraFile;
use vkdiff_networks::{ClipVisionConfig, ControlNetConfig};
use vkdiff_render::control::{ControlDepth, ControlKind};
use vkdiff_runtime::Dtype;
use vkdiff_setting::Message;

/// A ControlNet, the scene controls it sees and how it steers.
#[derive(Clone, Debug, PartialEq)]
pub struct ControlNetSettings {
    pub model: PathBuf,
    /// The controls it sees, in order: one for a plain ControlNet, one or more for a
    /// ControlNet-Union model (`control=depth+edges`).
    pub controls: Vec<ControlKind>,
    /// How a depth EXR maps to brightness.
    pub depth_mode: ControlDepth,
    pub scale: f32,
    pub start: f64,
    pub end: f64,
}

impl ControlNetSettings {
    /// The paper's one depth ControlNet, recorded as it always was.
    pub fn is_depth_only(&self) -> bool {
        self.controls == [ControlKind::Depth]
    }

    /// Its controls as `control=` takes them: `depth+edges`.
    pub fn controls_name(&self) -> String {
        self.controls.iter().map(|k| k.name()).collect::<Vec<_>>().join("+")
    }

    /// The value of `--controlnet` that gives these settings back.
    pub fn flag(&self) -> String {
        format!(
            "{},control={},scale={},start={},end={}",
            recorded_path(&self.model),
            self.controls_name(),
            self.scale,
            self.start,
            self.end
        )
    }
}

/// The IP-Adapter, its image encoder and its weight.
#[derive(Clone, Debug, PartialEq)]
pub struct IpAdapterSettings {
    pub adapter: PathBuf,
    pub encoder: PathBuf,
    pub scale: IpScale,
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
    /// A VAE in place of the model's (`--vae`): a diffusers folder or a single file.
    pub vae: Option<PathBuf>,
    /// A UNet in place of the model's (`--unet`): a diffusers folder or a file of its weights.
    pub unet: Option<PathBuf>,
    pub precision: Dtype,
    /// Every `--controlnet`, in order; their residuals are summed.
    pub controlnets: Vec<ControlNetSettings>,
    pub ip_adapter: Option<IpAdapterSettings>,
    pub loras: Vec<LoraSetting>,
    /// Whole or tiled VAE decodes (`--vae-tiling`).
    pub vae_tiling: VaeTilingSetting,
}

/// How settings and files record a model's path: a file or folder of a Hugging Face cache
/// snapshot as `ORG/NAME@COMMIT[/path/in/repo]`, the same on every machine whatever its cache
/// folder (and accepted back by every model flag); any other path as given.
pub fn recorded_path(path: &Path) -> String {
    let parts: Vec<&str> = path.iter().map(|p| p.to_str().unwrap_or("")).collect();
    for (i, part) in parts.iter().enumerate() {
        let Some((org, name)) = part.strip_prefix("models--").and_then(|r| r.split_once("--")) else { continue };
        if let (Some(&"snapshots"), Some(commit)) = (parts.get(i + 1), parts.get(i + 2)) {
            let inner: String = parts[i + 3..].iter().map(|p| format!("/{p}")).collect();
            return format!("{org}/{name}@{commit}{inner}");
        }
    }
    path.display().to_string()
}

impl ModelSettings {
    /// The components taken from elsewhere than the model.
    pub fn swaps(&self) -> Swaps<'_> {
        Swaps { vae: self.vae.as_deref(), unet: self.unet.as_deref() }
    }

    /// The LoRAs as `--lora` takes them, FILE:STRENGTH.
    pub fn lora_flags(&self) -> Vec<String> {
        self.loras.iter().map(|l| format!("{}:{}", recorded_path(&l.path), l.strength)).collect()
    }

    /// Settings that are wrong whatever the model, before anything loads.
    pub fn check(&self) -> Result<()> {
        for c in &self.controlnets {
            check_control_settings(c.scale, c.start, c.end)?;
        }
        if let Some(ip) = &self.ip_adapter {
            // The blocks named must hold cross-attentions of this UNet.
            let crosses = flagged(
                "model",
                &self.model,
                vkdiff_networks::read_unet_config(&self.model).and_then(|c| c.cross_attentions()),
            )?;
            ip.scale.per_layer(&crosses)?;
        }
        for (path, setting) in self.files() {
            if !path.exists() {
                return Err(Error::Setting(
                    Message::setting(setting).then(format!(" {}: no such file or folder", path.display())),
                ));
            }
        }
        // Headers and configs only: a file that is not what its flag wants fails before the
        // model loads.
        for lora in &self.loras {
            flagged("lora", &lora.path, LoraFile::open(&lora.path))?;
        }
        for c in &self.controlnets {
            flagged("controlnet", &c.model, check_controlnet_file(c))?;
        }
        if let Some(vae) = &self.vae {
            flagged("vae", vae, vkdiff_networks::AutoencoderKl::sdxl_config(vae))?;
        }
        if let Some(unet) = &self.unet {
            flagged("unet", unet, vkdiff_networks::check_swapped_unet(unet))?;
        }
        if let Some(ip) = &self.ip_adapter {
            flagged("image_encoder", &ip.encoder, ClipVisionConfig::from_file(&ip.encoder.join("config.json")))?;
            if ip.adapter.extension().is_some_and(|e| e == "safetensors") {
                flagged("ip_adapter", &ip.adapter, SafeTensors::open(&ip.adapter))?;
            }
        }
        Ok(())
    }

    /// Every control the ControlNets see, each once, in [`ControlKind`]'s order.
    pub fn control_kinds(&self) -> Vec<ControlKind> {
        let mut kinds: Vec<ControlKind> = self.controlnets.iter().flat_map(|c| c.controls.iter().copied()).collect();
        kinds.sort();
        kinds.dedup();
        kinds
    }

    /// Every file or folder the settings name, with the setting's name.
    fn files(&self) -> Vec<(&Path, &'static str)> {
        let mut files = vec![(self.model.as_path(), "model")];
        files.extend(self.vae.iter().map(|v| (v.as_path(), "vae")));
        files.extend(self.unet.iter().map(|u| (u.as_path(), "unet")));
        files.extend(self.controlnets.iter().map(|c| (c.model.as_path(), "controlnet")));
        if let Some(ip) = &self.ip_adapter {
            files.extend([(ip.adapter.as_path(), "ip_adapter"), (ip.encoder.as_path(), "image_encoder")]);
        }
        files.extend(self.loras.iter().map(|l| (l.path.as_path(), "lora")));
        files
    }
}

/// A ControlNet's config or header, and whether its kind takes its controls: a plain
/// ControlNet sees one, a ControlNet-Union model (`task_embedding`) one or more.
fn check_controlnet_file(c: &ControlNetSettings) -> Result<()> {
    if c.model.is_dir() {
        ControlNetConfig::from_file(&c.model.join("config.json"))?;
    }
    let union = match controlnet_weights(&c.model) {
        Some(file) => SafeTensors::open(&file)?.entries.contains_key("task_embedding"),
        None => false,
    };
    if c.controls.is_empty() || (c.controls.len() > 1 && !union) {
        return Err(Error::Setting(Message::setting("controlnet").then(format!(
            " control={}: a plain ControlNet sees one control; several need a ControlNet-Union model",
            c.controls_name()
        ))));
    }
    Ok(())
}

/// The safetensors file of a ControlNet given as a diffusers folder or as the file itself.
pub(crate) fn controlnet_weights(model: &Path) -> Option<PathBuf> {
    if !model.is_dir() {
        return Some(model.to_path_buf());
    }
    ["diffusion_pytorch_model.safetensors", "diffusion_pytorch_model.fp16.safetensors"]
        .into_iter()
        .map(|f| model.join(f))
        .find(|p| p.is_file())
}

/// `result`'s error, prefixed by the setting and file it came from.
pub(crate) fn flagged<T, E: Into<Error>>(setting: &str, path: &Path, result: std::result::Result<T, E>) -> Result<T> {
    result
        .map_err(|e| Error::Context(Message::setting(setting).then(format!(" {}", path.display())), Box::new(e.into())))
}

/// The scale must be a number and the range a non-empty part of [0, 1].
pub fn check_control_settings(scale: f32, start: f64, end: f64) -> Result<()> {
    if !scale.is_finite() {
        return Err(Error::Setting(Message::setting("control_scale").then(format!(" {scale} is not a number"))));
    }
    if !(0.0..=1.0).contains(&start) || !(0.0..=1.0).contains(&end) || start >= end {
        return Err(Error::Setting(
            Message::setting("control_start")
                .then(format!(" {start} and "))
                .and("control_end")
                .then(format!(" {end} must satisfy 0 <= start < end <= 1")),
        ));
    }
    Ok(())
}
