//! `vkdiff gen`'s guidance flags: the depth ControlNet, the IP-Adapter style images and the
//! LoRAs, each loaded and checked before any denoising starts.

use crate::scene_cmd::ControlMode;
use anyhow::{Context as _, Result};
use clap::Args;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use vkdiff_lora::LoraFile;
use vkdiff_pipeline::images::{load_control_image, read_image, ClipPreprocess};
use vkdiff_pipeline::{check_control_settings, ControlGuide, Guides, ImageGuide, RgbImage, Sdxl};
use vkdiff_runtime::Context;
use vkdiff_unet::{ClipVisionModelWithProjection, ControlNetModel, IpAdapter};

#[derive(Args, Debug)]
pub struct GuideArgs {
    /// Depth ControlNet: a diffusers folder, or one .safetensors in the diffusers or original
    /// (cldm) layout.
    #[arg(long, requires = "depth")]
    controlnet: Option<PathBuf>,
    /// The ControlNet's input: a metric-depth EXR (channel Z, <layer>.Depth.Z, V or R), turned
    /// into an image as `vkdiff scene` writes control.png, or an image used as it is.
    #[arg(long, requires = "controlnet")]
    depth: Option<PathBuf>,
    /// How a depth EXR maps to brightness (near is bright either way).
    #[arg(long, value_enum, default_value_t = ControlMode::Inverse)]
    control_depth: ControlMode,
    /// Multiplies the ControlNet's residuals (diffusers' controlnet_conditioning_scale).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    control_scale: f32,
    /// Fraction of the steps before which the ControlNet is off.
    #[arg(long, default_value_t = 0.0)]
    control_start: f64,
    /// Fraction of the steps after which the ControlNet is off.
    #[arg(long, default_value_t = 1.0)]
    control_end: f64,
    /// IP-Adapter for SDXL (h94 layout, .safetensors, plain or plus): style images steer the look.
    #[arg(long, requires_all = ["image_encoder", "ip_image"])]
    ip_adapter: Option<PathBuf>,
    /// The adapter's CLIP vision encoder: a folder with config.json and model.safetensors
    /// (and preprocessor_config.json, else CLIP's defaults at the encoder's image size).
    #[arg(long, requires = "ip_adapter")]
    image_encoder: Option<PathBuf>,
    /// A style image for --ip-adapter; repeat it for several, whose tokens are joined as
    /// diffusers joins several images given to one adapter.
    #[arg(long, requires = "ip_adapter")]
    ip_image: Vec<PathBuf>,
    /// Weight of the image tokens' attention.
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    ip_scale: f32,
    /// A LoRA (kohya or diffusers/PEFT .safetensors) as FILE or FILE:STRENGTH (default 1);
    /// repeat it for several. Merged into the weights on the device.
    #[arg(long, value_parser = parse_lora)]
    lora: Vec<LoraArg>,
}

#[derive(Clone, Debug)]
pub struct LoraArg {
    path: PathBuf,
    strength: f32,
}

/// `FILE[:STRENGTH]`; a colon whose tail is not a number belongs to the path.
fn parse_lora(text: &str) -> std::result::Result<LoraArg, String> {
    let (path, strength) = match text.rsplit_once(':').map(|(p, s)| (p, s.parse::<f32>())) {
        Some((p, Ok(s))) if s.is_finite() => (p, s),
        _ => (text, 1.0),
    };
    if path.is_empty() {
        return Err("expected FILE or FILE:STRENGTH".into());
    }
    Ok(LoraArg { path: path.into(), strength })
}

struct StyleImages {
    adapter: IpAdapter,
    encoder: ClipVisionModelWithProjection,
    preprocess: ClipPreprocess,
    images: Vec<RgbImage>,
}

/// The guides' models and inputs, loaded.
pub struct LoadedGuides {
    control: Option<(ControlNetModel, RgbImage)>,
    style: Option<StyleImages>,
    loras: Vec<(LoraFile, f32)>,
}

impl GuideArgs {
    /// Flag values that are wrong whatever the model, before anything loads.
    pub fn check(&self) -> Result<()> {
        if self.controlnet.is_some() {
            check_control_settings(self.control_scale, self.control_start, self.control_end)?;
        }
        Ok(())
    }

    pub fn load(&self, ctx: &Context, model: &Sdxl) -> Result<LoadedGuides> {
        let control = match (&self.controlnet, &self.depth) {
            (Some(net), Some(depth)) => {
                eprintln!("loading ControlNet {}", net.display());
                let image = load_control_image(depth, self.control_depth.into()).with_context(|| format!("--depth {}", depth.display()))?;
                let net = ControlNetModel::load(ctx, net, model.unet_config(), model.dtype()).with_context(|| format!("--controlnet {}", net.display()))?;
                Some((net, image))
            }
            _ => None,
        };
        let style = match (&self.ip_adapter, &self.image_encoder) {
            (Some(adapter), Some(encoder)) => Some(self.load_style(ctx, model, adapter, encoder)?),
            _ => None,
        };
        let loras = self
            .lora
            .iter()
            .map(|l| Ok((LoraFile::open(&l.path).with_context(|| format!("--lora {}", l.path.display()))?, l.strength)))
            .collect::<Result<_>>()?;
        Ok(LoadedGuides { control, style, loras })
    }

    fn load_style(&self, ctx: &Context, model: &Sdxl, adapter: &Path, encoder: &Path) -> Result<StyleImages> {
        eprintln!("loading IP-Adapter {} and image encoder {}", adapter.display(), encoder.display());
        let images = self.ip_image.iter().map(|p| read_image(p).with_context(|| format!("--ip-image {}", p.display()))).collect::<Result<_>>()?;
        let what = || format!("--image-encoder {}", encoder.display());
        let encoder_model = ClipVisionModelWithProjection::load_folder(ctx, encoder, model.dtype()).with_context(what)?;
        let config = [encoder.join("preprocessor_config.json"), encoder.join("image_encoder/preprocessor_config.json")].into_iter().find(|p| p.is_file());
        let preprocess = match config {
            Some(path) => ClipPreprocess::from_file(&path).with_context(what)?,
            None => ClipPreprocess::square(encoder_model.config().image_size),
        };
        let adapter = IpAdapter::load(ctx, adapter, model.unet(), model.dtype()).with_context(|| format!("--ip-adapter {}", adapter.display()))?;
        Ok(StyleImages { adapter, encoder: encoder_model, preprocess, images })
    }

    /// The flags as PNG text chunks.
    pub fn settings(&self, m: &mut BTreeMap<String, String>) {
        if let (Some(net), Some(depth)) = (&self.controlnet, &self.depth) {
            m.insert("controlnet".into(), net.display().to_string());
            m.insert("depth".into(), depth.display().to_string());
            m.insert("control_depth".into(), format!("{:?}", self.control_depth).to_lowercase());
            m.insert("control_scale".into(), self.control_scale.to_string());
            m.insert("control_start".into(), self.control_start.to_string());
            m.insert("control_end".into(), self.control_end.to_string());
        }
        if let Some(adapter) = &self.ip_adapter {
            m.insert("ip_adapter".into(), adapter.display().to_string());
            m.insert("image_encoder".into(), self.image_encoder.as_deref().unwrap_or(Path::new("")).display().to_string());
            m.insert("ip_images".into(), self.ip_image.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join("\n"));
            m.insert("ip_scale".into(), self.ip_scale.to_string());
        }
        if !self.lora.is_empty() {
            m.insert("loras".into(), self.lora_list("\n"));
        }
    }

    fn lora_list(&self, separator: &str) -> String {
        self.lora.iter().map(|l| format!("{}:{}", l.path.display(), l.strength)).collect::<Vec<_>>().join(separator)
    }

    /// The A1111-style summary of the guides, appended to `parameters`.
    pub fn summary(&self) -> String {
        let mut parts = Vec::new();
        if let Some(net) = &self.controlnet {
            parts.push(format!(
                "ControlNet: {}, Control scale: {}, Control range: {}-{}",
                net.display(),
                self.control_scale,
                self.control_start,
                self.control_end
            ));
        }
        if let Some(adapter) = &self.ip_adapter {
            parts.push(format!("IP-Adapter: {}, IP images: {}, IP scale: {}", adapter.display(), self.ip_image.len(), self.ip_scale));
        }
        if !self.lora.is_empty() {
            parts.push(format!("LoRAs: {}", self.lora_list(" ")));
        }
        parts.iter().map(|p| format!(", {p}")).collect()
    }
}

impl LoadedGuides {
    /// Merges the LoRAs into `model`'s weights, telling what each one touched.
    pub fn merge_loras(&self, model: &mut Sdxl) -> Result<()> {
        let loras: Vec<(&LoraFile, f32)> = self.loras.iter().map(|(f, s)| (f, *s)).collect();
        if let Some(summary) = model.set_loras(&loras)? {
            eprintln!("{summary}");
        }
        Ok(())
    }

    pub fn guides<'a>(&'a self, args: &GuideArgs) -> Guides<'a> {
        Guides { control: self.control(args), image: self.image(args) }
    }

    fn image<'a>(&'a self, args: &GuideArgs) -> Option<ImageGuide<'a>> {
        self.style.as_ref().map(|s| ImageGuide { adapter: &s.adapter, encoder: &s.encoder, preprocess: &s.preprocess, images: &s.images, scale: args.ip_scale })
    }

    fn control<'a>(&'a self, args: &GuideArgs) -> Option<ControlGuide<'a>> {
        self.control.as_ref().map(|(net, image)| ControlGuide { net, image, scale: args.control_scale, start: args.control_start, end: args.control_end })
    }
}
