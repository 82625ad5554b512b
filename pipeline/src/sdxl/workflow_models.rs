//! The paper's workflow loaded once: SDXL, the depth ControlNet, the IP-Adapter with its image
//! encoder, and the LoRAs merged into the weights. `vkdiff gen` loads it for one image,
//! `vkdiff dataset` for thousands.

use crate::error::Result;
use crate::images::ClipPreprocess;
use crate::sdxl::controlnet_guide::{ControlGuide, ControlNetUse};
use crate::sdxl::denoiser::IpAdapterUse;
use crate::sdxl::Guides;
use crate::sdxl::ImageGuide;
use crate::sdxl::Sdxl;
use crate::settings::{flagged, GuideInputs, ModelSettings};
use crate::RgbImage;
use std::path::Path;
use vkdiff_lora::LoraFile;
use vkdiff_networks::{ClipVisionModelWithProjection, ControlNetModel, IpAdapter};
use vkdiff_runtime::Context;

/// An IP-Adapter with the encoder and preprocessing of its style images.
pub struct StyleModels {
    pub adapter: IpAdapter,
    pub encoder: ClipVisionModelWithProjection,
    pub preprocess: ClipPreprocess,
}

pub struct WorkflowModels {
    pub sdxl: Sdxl,
    pub controlnet: Option<ControlNetModel>,
    pub style: Option<StyleModels>,
    pub settings: ModelSettings,
}

impl WorkflowModels {
    /// Loads every model `settings` names and merges the LoRAs; `log` hears what is loading and
    /// what each LoRA touched.
    pub fn load(ctx: &Context, settings: &ModelSettings, log: &mut dyn FnMut(&str)) -> Result<WorkflowModels> {
        let dtype = settings.precision;
        let mut sdxl = Sdxl::load_with(ctx, &settings.model, settings.swaps(), dtype, &mut |part| {
            log(&format!("loading {part}"))
        })?;
        let controlnet = match &settings.controlnet {
            Some(c) => {
                log(&format!("loading ControlNet {}", c.model.display()));
                Some(flagged("controlnet", &c.model, ControlNetModel::load(ctx, &c.model, sdxl.unet_config(), dtype))?)
            }
            None => None,
        };
        let style =
            settings.ip_adapter.as_ref().map(|ip| load_style(ctx, &sdxl, &ip.adapter, &ip.encoder, log)).transpose()?;
        let loras = settings
            .loras
            .iter()
            .map(|l| Ok((flagged("lora", &l.path, LoraFile::open(&l.path))?, l.strength)))
            .collect::<Result<Vec<_>>>()?;
        let refs: Vec<(&LoraFile, f32)> = loras.iter().map(|(f, s)| (f, *s)).collect();
        if let Some(summary) = sdxl.set_loras(&refs)? {
            log(&summary.to_string());
        }
        Ok(WorkflowModels { sdxl, controlnet, style, settings: settings.clone() })
    }

    /// The ControlNets as a batch uses them.
    pub fn control_uses(&self) -> Vec<ControlNetUse<'_>> {
        let pairs = self.controlnet.iter().zip(&self.settings.controlnet);
        pairs.map(|(net, c)| ControlNetUse { net, scale: c.scale, start: c.start, end: c.end }).collect()
    }

    /// The IP-Adapter as a batch of images with `images` style images each uses it.
    pub fn ip_use(&self, images: usize) -> Option<IpAdapterUse<'_>> {
        let (style, ip) = (self.style.as_ref()?, self.settings.ip_adapter.as_ref()?);
        Some(IpAdapterUse { adapter: &style.adapter, scale: &ip.scale, images })
    }

    /// The IP-Adapter over `images`.
    pub fn image_guide<'a>(&'a self, images: &'a [RgbImage]) -> Option<ImageGuide<'a>> {
        let (style, ip) = (self.style.as_ref()?, self.settings.ip_adapter.as_ref()?);
        Some(ImageGuide {
            adapter: &style.adapter,
            encoder: &style.encoder,
            preprocess: &style.preprocess,
            images,
            scale: &ip.scale,
        })
    }

    /// One image's guides over its inputs.
    pub fn guides<'a>(&'a self, inputs: &'a GuideInputs) -> Guides<'a> {
        let images = inputs.control.iter();
        let control = self
            .control_uses()
            .into_iter()
            .zip(images)
            .map(|(c, image)| ControlGuide { net: c.net, image, scale: c.scale, start: c.start, end: c.end })
            .collect();
        Guides { control, image: self.image_guide(&inputs.style), init: inputs.init.as_ref() }
    }
}

fn load_style(
    ctx: &Context,
    sdxl: &Sdxl,
    adapter: &Path,
    encoder: &Path,
    log: &mut dyn FnMut(&str),
) -> Result<StyleModels> {
    log(&format!("loading IP-Adapter {} and image encoder {}", adapter.display(), encoder.display()));
    let encoder_model =
        flagged("image_encoder", encoder, ClipVisionModelWithProjection::load_folder(ctx, encoder, sdxl.dtype()))?;
    let config = [encoder.join("preprocessor_config.json"), encoder.join("image_encoder/preprocessor_config.json")]
        .into_iter()
        .find(|p| p.is_file());
    let preprocess = match config {
        Some(path) => flagged("image_encoder", encoder, ClipPreprocess::from_file(&path))?,
        None => ClipPreprocess::square(encoder_model.config().image_size),
    };
    let adapter = flagged("ip_adapter", adapter, IpAdapter::load(ctx, adapter, sdxl.unet(), sdxl.dtype()))?;
    Ok(StyleModels { adapter, encoder: encoder_model, preprocess })
}
