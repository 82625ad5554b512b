//! Where a LoRA module lands: dictionaries from kohya's flattened names (both the original sgm
//! paths and the diffusers paths for the UNet, transformers paths for the text encoders) to the
//! device parameters of the loaded networks, built from the networks' own names.

use crate::component::Component;
use crate::error::Result;
use crate::format::Address;
use std::collections::HashMap;
use vkdiff_networks::{unet_names, ClipTextModel, Parameter, Parameters, UNet, UNetConfig};

/// The networks a merge edits. A component left out makes LoRA modules aimed at it unmatched.
#[derive(Clone, Copy)]
pub struct Targets<'a> {
    pub unet: Option<(&'a Parameters, &'a UNetConfig)>,
    pub text_encoder_1: Option<&'a Parameters>,
    pub text_encoder_2: Option<&'a Parameters>,
}

impl<'a> Targets<'a> {
    /// SDXL: the UNet, CLIP-L and OpenCLIP bigG.
    pub fn sdxl(unet: &'a UNet, clip_l: &'a ClipTextModel, big_g: &'a ClipTextModel) -> Targets<'a> {
        Targets {
            unet: Some((unet.parameters(), unet.config())),
            text_encoder_1: Some(clip_l.parameters()),
            text_encoder_2: Some(big_g.parameters()),
        }
    }

    pub fn unet_only(unet: &'a UNet) -> Targets<'a> {
        Targets { unet: Some((unet.parameters(), unet.config())), text_encoder_1: None, text_encoder_2: None }
    }
}

/// Where a module's address points.
pub(crate) enum Resolved<'a> {
    Weight(String, &'a Parameter),
    /// A weight of a module the network never runs: nothing to change.
    NotRun,
    Missing,
}

/// One network's parameters and the kohya names of its weights.
pub(crate) struct Dictionary<'a> {
    params: &'a Parameters,
    kohya: HashMap<String, String>,
}

/// Text-encoder layer modules kohya adapts; registered for every layer index up to the deepest
/// present, so that a key aimed at a layer the network never loaded is still recognised.
const CLIP_LAYER_MODULES: [&str; 6] =
    ["self_attn.q_proj", "self_attn.k_proj", "self_attn.v_proj", "self_attn.out_proj", "mlp.fc1", "mlp.fc2"];

impl<'a> Dictionary<'a> {
    pub fn unet(params: &'a Parameters, config: &UNetConfig) -> Result<Dictionary<'a>> {
        let original = unet_names(config)?;
        let mut d = Dictionary::plain(params);
        for name in weights(params) {
            if let Some(stored) = original.rename(name) {
                if let Some(module) = stored.name.strip_suffix(".weight") {
                    d.kohya.entry(flat(module)).or_insert_with(|| name.to_string());
                }
            }
        }
        Ok(d)
    }

    pub fn text(params: &'a Parameters) -> Dictionary<'a> {
        let mut d = Dictionary::plain(params);
        let layer = |n: &str| n.strip_prefix("text_model.encoder.layers.")?.split('.').next()?.parse::<usize>().ok();
        let deepest = params.names().into_iter().filter_map(layer).max().map_or(0, |l| l + 2);
        for i in 0..deepest {
            for m in CLIP_LAYER_MODULES {
                let module = format!("text_model.encoder.layers.{i}.{m}");
                d.kohya.entry(flat(&module)).or_insert_with(|| format!("{module}.weight"));
            }
        }
        d
    }

    /// The diffusers / transformers spelling of every weight (what kohya files from converters use).
    fn plain(params: &'a Parameters) -> Dictionary<'a> {
        let kohya = weights(params).filter_map(|n| Some((flat(n.strip_suffix(".weight")?), n.to_string()))).collect();
        Dictionary { params, kohya }
    }

    pub fn resolve(&self, address: &Address) -> Resolved<'a> {
        let name = match address {
            Address::Kohya(k) => match self.kohya.get(k) {
                Some(n) => n.clone(),
                None => return Resolved::Missing,
            },
            // transformers 5's CLIPTextModel has no `text_model` level, so files saved under it
            // name CLIP-L's modules `encoder.layers.N…`; the networks here keep the level.
            Address::Path(p) => {
                let (plain, leveled) = (format!("{p}.weight"), format!("text_model.{p}.weight"));
                let known = |n: &str| self.params.get(n).is_some() || self.params.is_not_run(n);
                if !known(&plain) && known(&leveled) {
                    leveled
                } else {
                    plain
                }
            }
        };
        match self.params.get(&name) {
            Some(p) => Resolved::Weight(name, p),
            None if self.params.is_not_run(&name) => Resolved::NotRun,
            None => Resolved::Missing,
        }
    }
}

/// The dictionaries of the networks present in `targets`.
pub(crate) fn dictionaries<'a>(targets: &Targets<'a>) -> Result<HashMap<Component, Dictionary<'a>>> {
    let mut out = HashMap::new();
    if let Some((params, config)) = targets.unet {
        out.insert(Component::Unet, Dictionary::unet(params, config)?);
    }
    for (component, params) in
        [(Component::TextEncoder1, targets.text_encoder_1), (Component::TextEncoder2, targets.text_encoder_2)]
    {
        if let Some(params) = params {
            out.insert(component, Dictionary::text(params));
        }
    }
    Ok(out)
}

/// Names of matrix and conv weights: what a LoRA can adapt.
fn weights(params: &Parameters) -> impl Iterator<Item = &str> {
    params
        .names()
        .into_iter()
        .filter(|n| n.ends_with(".weight") && params.get(n).is_some_and(|p| p.torch_shape.len() >= 2))
}

fn flat(module: &str) -> String {
    module.replace('.', "_")
}
