//! What loads once per process: the SDXL model, its depth ControlNet, its IP-Adapter and the
//! LoRAs merged into it; checked before anything loads.

use crate::error::{Error, Result};
use crate::sdxl::Swaps;
use crate::settings::ip_scale::IpScale;
use crate::settings::VaeTilingSetting;
use std::path::{Path, PathBuf};
use vkdiff_formats::SafeTensors;
use vkdiff_lora::LoraFile;
use vkdiff_networks::{ClipVisionConfig, ControlNetConfig};
use vkdiff_render::control::ControlDepth;
use vkdiff_runtime::Dtype;
use vkdiff_setting::Message;

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
    pub controlnet: Option<ControlNetSettings>,
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
        if let Some(c) = &self.controlnet {
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
        if let Some(c) = &self.controlnet {
            let checked = if c.model.is_dir() {
                ControlNetConfig::from_file(&c.model.join("config.json")).map(drop)
            } else {
                SafeTensors::open(&c.model).map(drop).map_err(Into::into)
            };
            flagged("controlnet", &c.model, checked)?;
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

    /// Every file or folder the settings name, with the setting's name.
    fn files(&self) -> Vec<(&Path, &'static str)> {
        let mut files = vec![(self.model.as_path(), "model")];
        files.extend(self.vae.iter().map(|v| (v.as_path(), "vae")));
        files.extend(self.unet.iter().map(|u| (u.as_path(), "unet")));
        files.extend(self.controlnet.iter().map(|c| (c.model.as_path(), "controlnet")));
        if let Some(ip) = &self.ip_adapter {
            files.extend([(ip.adapter.as_path(), "ip_adapter"), (ip.encoder.as_path(), "image_encoder")]);
        }
        files.extend(self.loras.iter().map(|l| (l.path.as_path(), "lora")));
        files
    }
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
