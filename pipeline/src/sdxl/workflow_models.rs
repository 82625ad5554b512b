//! The paper's workflow loaded once: SDXL, its ControlNets, the IP-Adapter with its image
//! encoder, and the LoRAs merged into the weights. `vkdiff gen` loads it for one image,
//! `vkdiff dataset` for thousands.

use crate::error::{Error, Result};
use crate::images::ClipPreprocess;
use crate::sdxl::controlnet_guide::{union_control_type, ControlGuide, ControlNetUse};
use crate::sdxl::denoiser::IpAdapterUse;
use crate::sdxl::Guides;
use crate::sdxl::ImageGuide;
use crate::sdxl::Sdxl;
use crate::settings::models::controlnet_weights;
use crate::settings::{flagged, GuideInputs, ModelSettings};
use crate::RgbImage;
use std::path::Path;
use vkdiff_formats::SafeTensors;
use vkdiff_lora::LoraFile;
use vkdiff_networks::{ClipVisionModelWithProjection, ControlNetModel, IpAdapter};
use vkdiff_render::control::ControlKind;
use vkdiff_runtime::{dtype_size, Context, Dtype};
use vkdiff_setting::Message;

/// An IP-Adapter with the encoder and preprocessing of its style images.
pub struct StyleModels {
    pub adapter: IpAdapter,
    pub encoder: ClipVisionModelWithProjection,
    pub preprocess: ClipPreprocess,
}

pub struct WorkflowModels {
    pub sdxl: Sdxl,
    /// One per `--controlnet`, with a Union model's control type of each control it sees
    /// (empty for a plain ControlNet).
    pub controlnets: Vec<(ControlNetModel, Vec<usize>)>,
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
        let controlnets = (settings.controlnets.iter())
            .map(|c| {
                check_room_for(ctx, &c.model, dtype)?;
                log(&format!("loading ControlNet {}", c.model.display()));
                let net =
                    flagged("controlnet", &c.model, ControlNetModel::load(ctx, &c.model, sdxl.unet_config(), dtype))?;
                let types = flagged("controlnet", &c.model, union_control_types(&net, &c.controls))?;
                Ok((net, types))
            })
            .collect::<Result<Vec<_>>>()?;
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
        Ok(WorkflowModels { sdxl, controlnets, style, settings: settings.clone() })
    }

    /// The ControlNets as a batch uses them.
    pub fn control_uses(&self) -> Vec<ControlNetUse<'_>> {
        let pairs = self.controlnets.iter().zip(&self.settings.controlnets);
        pairs
            .map(|((net, types), c)| ControlNetUse {
                net,
                control_types: types,
                scale: c.scale,
                start: c.start,
                end: c.end,
            })
            .collect()
    }

    /// Each ControlNet's images from `controls`, in the order of the controls it sees.
    pub fn control_images<'a>(&self, controls: &impl Fn(ControlKind) -> &'a RgbImage) -> Vec<Vec<&'a RgbImage>> {
        self.settings.controlnets.iter().map(|c| c.controls.iter().map(|&k| controls(k)).collect()).collect()
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
        let images = self.control_images(&|kind| &inputs.controls[&kind]);
        let control =
            self.control_uses().into_iter().zip(images).map(|(use_, images)| ControlGuide { use_, images }).collect();
        Guides { control, image: self.image_guide(&inputs.style), init: inputs.init.as_ref(), ..Default::default() }
    }
}

/// A ControlNet's weights must fit the device's room left by the model and the ControlNets before
/// it, or the run stops before they load, with the figures. The cross-attentions' key and value
/// weights stay in host memory; the rest is on the device, in the run's precision.
fn check_room_for(ctx: &Context, model: &Path, dtype: Dtype) -> Result<()> {
    let Some(file) = controlnet_weights(model) else { return Ok(()) };
    let header = flagged("controlnet", model, SafeTensors::open(&file))?;
    let on_device = |name: &str| !(name.contains("attn2.to_k.") || name.contains("attn2.to_v."));
    let need: u64 = (header.entries.iter())
        .filter(|(name, _)| on_device(name))
        .map(|(_, e)| e.shape.iter().product::<usize>() as u64 * dtype_size(dtype) as u64)
        .sum();
    let room = ctx.memory_room();
    if need <= room.free {
        return Ok(());
    }
    Err(Error::Setting(Message::setting("controlnet").then(format!(
        " {}: its weights need {} MiB of device memory and {} MiB are free by {} after the model and the \
        ControlNets before it; a ControlNet-Union model sees several controls for the memory of one \
        (control=depth+edges)",
        model.display(),
        need.div_ceil(1 << 20),
        room.free >> 20,
        room.source
    ))))
}

/// A Union model's control type of each of `controls` (its `control_mode`); none for a plain
/// ControlNet, which sees one control.
fn union_control_types(net: &ControlNetModel, controls: &[ControlKind]) -> Result<Vec<usize>> {
    match net.control_types() {
        None if controls.len() == 1 => Ok(Vec::new()),
        None => Err(Error::Setting(Message::setting("controlnet").then(format!(
            " sees {} controls: a plain ControlNet sees one; several need a ControlNet-Union model",
            controls.len()
        )))),
        Some(_) => Ok(controls.iter().map(|&k| union_control_type(k)).collect()),
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
