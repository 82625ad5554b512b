//! The paper's workflow loaded once: SDXL, the depth ControlNet, the IP-Adapter with its image
//! encoder, and the LoRAs merged into the weights. `vkdiff gen` loads it for one image,
//! `vkdiff dataset` for thousands.

use crate::controlnet_guide::{check_control_settings, ControlGuide, ControlNetUse};
use crate::denoiser::IpAdapterUse;
use crate::error::{Error, Result};
use crate::gen_settings::{GenSettings, ModelSettings};
use crate::images::{load_control_image, read_image, ClipPreprocess};
use crate::ip_adapter_guide::ImageGuide;
use crate::sdxl::Sdxl;
use crate::text_to_image::Guides;
use crate::RgbImage;
use std::path::Path;
use vkdiff_formats::SafeTensors;
use vkdiff_lora::LoraFile;
use vkdiff_networks::{ClipVisionConfig, ClipVisionModelWithProjection, ControlNetConfig, ControlNetModel, IpAdapter};
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

/// `result`'s error, prefixed by the flag and file it came from.
pub(crate) fn flagged<T, E: Into<Error>>(flag: &str, path: &Path, result: std::result::Result<T, E>) -> Result<T> {
    result.map_err(|e| Error::Context(format!("{flag} {}", path.display()), Box::new(e.into())))
}

impl ModelSettings {
    /// Flag values that are wrong whatever the model, before anything loads.
    pub fn check(&self) -> Result<()> {
        if let Some(c) = &self.controlnet {
            check_control_settings(c.scale, c.start, c.end)?;
        }
        if let Some(ip) = &self.ip_adapter {
            // The blocks named must hold cross-attentions of this UNet.
            let crosses = flagged(
                "--model",
                &self.model,
                vkdiff_networks::read_unet_config(&self.model).and_then(|c| c.cross_attentions()),
            )?;
            ip.scale.per_layer(&crosses)?;
        }
        for (path, flag) in self.files() {
            if !path.exists() {
                return Err(Error::Config(format!("{flag} {}: no such file or folder", path.display())));
            }
        }
        // Headers and configs only: a file that is not what its flag wants fails before the
        // model loads.
        for lora in &self.loras {
            flagged("--lora", &lora.path, LoraFile::open(&lora.path))?;
        }
        if let Some(c) = &self.controlnet {
            let checked = if c.model.is_dir() {
                ControlNetConfig::from_file(&c.model.join("config.json")).map(drop)
            } else {
                SafeTensors::open(&c.model).map(drop).map_err(Into::into)
            };
            flagged("--controlnet", &c.model, checked)?;
        }
        if let Some(ip) = &self.ip_adapter {
            flagged("--image-encoder", &ip.encoder, ClipVisionConfig::from_file(&ip.encoder.join("config.json")))?;
            if ip.adapter.extension().is_some_and(|e| e == "safetensors") {
                flagged("--ip-adapter", &ip.adapter, SafeTensors::open(&ip.adapter))?;
            }
        }
        Ok(())
    }

    /// Every file or folder the settings name, with its flag.
    fn files(&self) -> Vec<(&Path, &'static str)> {
        let mut files = vec![(self.model.as_path(), "--model")];
        files.extend(self.controlnet.iter().map(|c| (c.model.as_path(), "--controlnet")));
        if let Some(ip) = &self.ip_adapter {
            files.extend([(ip.adapter.as_path(), "--ip-adapter"), (ip.encoder.as_path(), "--image-encoder")]);
        }
        files.extend(self.loras.iter().map(|l| (l.path.as_path(), "--lora")));
        files
    }
}

impl WorkflowModels {
    /// Loads every model `settings` names and merges the LoRAs; `log` hears what is loading and
    /// what each LoRA touched.
    pub fn load(ctx: &Context, settings: &ModelSettings, log: &mut dyn FnMut(&str)) -> Result<WorkflowModels> {
        let dtype = settings.precision;
        let mut sdxl = Sdxl::load(ctx, &settings.model, dtype, &mut |part| log(&format!("loading {part}")))?;
        let controlnet = match &settings.controlnet {
            Some(c) => {
                log(&format!("loading ControlNet {}", c.model.display()));
                Some(flagged(
                    "--controlnet",
                    &c.model,
                    ControlNetModel::load(ctx, &c.model, sdxl.unet_config(), dtype),
                )?)
            }
            None => None,
        };
        let style =
            settings.ip_adapter.as_ref().map(|ip| load_style(ctx, &sdxl, &ip.adapter, &ip.encoder, log)).transpose()?;
        let loras = settings
            .loras
            .iter()
            .map(|l| Ok((flagged("--lora", &l.path, LoraFile::open(&l.path))?, l.strength)))
            .collect::<Result<Vec<_>>>()?;
        let refs: Vec<(&LoraFile, f32)> = loras.iter().map(|(f, s)| (f, *s)).collect();
        if let Some(summary) = sdxl.set_loras(&refs)? {
            log(&summary.to_string());
        }
        Ok(WorkflowModels { sdxl, controlnet, style, settings: settings.clone() })
    }

    /// The ControlNet as a batch uses it.
    pub fn control_use(&self) -> Option<ControlNetUse<'_>> {
        let (net, c) = (self.controlnet.as_ref()?, self.settings.controlnet.as_ref()?);
        Some(ControlNetUse { net, scale: c.scale, start: c.start, end: c.end })
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
        let control = self.control_use().zip(inputs.control.as_ref()).map(|(c, image)| ControlGuide {
            net: c.net,
            image,
            scale: c.scale,
            start: c.start,
            end: c.end,
        });
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
        flagged("--image-encoder", encoder, ClipVisionModelWithProjection::load_folder(ctx, encoder, sdxl.dtype()))?;
    let config = [encoder.join("preprocessor_config.json"), encoder.join("image_encoder/preprocessor_config.json")]
        .into_iter()
        .find(|p| p.is_file());
    let preprocess = match config {
        Some(path) => flagged("--image-encoder", encoder, ClipPreprocess::from_file(&path))?,
        None => ClipPreprocess::square(encoder_model.config().image_size),
    };
    let adapter = flagged("--ip-adapter", adapter, IpAdapter::load(ctx, adapter, sdxl.unet(), sdxl.dtype()))?;
    Ok(StyleModels { adapter, encoder: encoder_model, preprocess })
}

/// The images one generation's guides read: the ControlNet's and the style images.
#[derive(Default)]
pub struct GuideInputs {
    pub control: Option<RgbImage>,
    pub style: Vec<RgbImage>,
    /// img2img's init image.
    pub init: Option<RgbImage>,
}

impl GenSettings {
    /// Reads the input images the settings name (before any model loads, so a bad file fails fast).
    pub fn read_inputs(&self) -> Result<GuideInputs> {
        let control = match (&self.models.controlnet, &self.depth) {
            (Some(c), Some(depth)) => Some(flagged("--depth", depth, load_control_image(depth, c.depth_mode))?),
            (Some(_), None) => return Err(Error::Config("--controlnet needs --depth".into())),
            (None, _) => None,
        };
        let style = if self.models.ip_adapter.is_some() {
            if self.ip_images.is_empty() {
                return Err(Error::Config("--ip-adapter needs at least one --ip-image".into()));
            }
            read_images(&self.ip_images)?
        } else {
            Vec::new()
        };
        let init = self.init_image.as_ref().map(|p| flagged("--init-image", p, read_image(p))).transpose()?;
        Ok(GuideInputs { control, style, init })
    }
}

/// Style images, each error naming its `--ip-image`.
pub fn read_images(paths: &[std::path::PathBuf]) -> Result<Vec<RgbImage>> {
    paths.iter().map(|p| flagged("--ip-image", p, read_image(p))).collect()
}
