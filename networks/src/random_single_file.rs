//! SDXL with the benchmarks' random weights written as one file in the original (sgm) layout,
//! f16: what a peer that reads only that layout (stable-diffusion.cpp) loads, so that vkdiff and
//! it time the same weights. The names go backwards through the renaming tables the single-file
//! loaders read by (held to diffusers' converters); the values are [`Checkpoint::random`]'s,
//! drawn again by name as each tensor is written, so the file never sits in memory whole.

use crate::clip::{open_clip_names, ClipTextConfig, ClipTextModel, TextEncoderSlot};
use crate::error::Result;
use crate::unet::{unet_names, UNet, UNetConfig};
use crate::vae::{vae_names, AutoencoderKl, VaeConfig};
use crate::weights::{transpose, Checkpoint, OriginalNames};
use std::collections::BTreeMap;
use std::path::Path;
use vkdiff_runtime::{Context, Dtype};

/// The four networks of an SDXL checkpoint.
#[derive(Clone)]
pub struct SdxlConfigs {
    pub unet: UNetConfig,
    pub clip_l: ClipTextConfig,
    pub big_g: ClipTextConfig,
    pub vae: VaeConfig,
}

impl SdxlConfigs {
    /// SDXL base 1.0's.
    pub fn sdxl_base() -> SdxlConfigs {
        fn parse<T: serde::de::DeserializeOwned>(text: &str) -> T {
            serde_json::from_str(text).expect("the built-in configs parse")
        }
        SdxlConfigs {
            unet: UNetConfig::sdxl_base(),
            clip_l: parse(crate::SDXL_CLIP_L_CONFIG),
            big_g: parse(crate::SDXL_BIGG_CONFIG),
            vae: parse(crate::SDXL_VAE_CONFIG),
        }
    }
}

/// The random checkpoints' seeds, as `Sdxl::random_sdxl_base` draws them.
pub const RANDOM_SEEDS: RandomSeeds = RandomSeeds { clip_l: 1, big_g: 2, unet: 3, vae: 4 };

pub struct RandomSeeds {
    pub clip_l: u64,
    pub big_g: u64,
    pub unet: u64,
    pub vae: u64,
}

/// One stored tensor: its original name and shape, and the diffusers tensors it holds (row
/// blocks of a fused one), each with its block's index, seed and PyTorch shape.
struct Stored {
    name: String,
    shape: Vec<usize>,
    transposed: bool,
    parts: Vec<(usize, u64, String, Vec<usize>)>,
    /// The value of a tensor no network reads (parts empty).
    constant: f32,
}

/// Writes SDXL with `configs` and random weights of [`RANDOM_SEEDS`] to `path` in the original
/// layout, f16, atomically. Each network is built once on `ctx` from a random checkpoint to learn
/// the tensors it reads; CLIP-L is built one layer deeper, with its final norm, and bigG's
/// `logit_scale` is added, since the layout holds what SDXL leaves unused. Returns the bytes
/// written.
pub fn write_random_single_file(ctx: &Context, configs: &SdxlConfigs, path: &Path) -> Result<u64> {
    let mut stored: Vec<Stored> = Vec::new();
    let requests = |seed: u64, build: &dyn Fn(&Checkpoint) -> Result<()>| -> Result<Vec<(String, Vec<usize>)>> {
        let ckpt = Checkpoint::random(ctx, Dtype::F16, seed);
        build(&ckpt)?;
        Ok(ckpt.requests())
    };
    let clip_l = ClipTextConfig { num_hidden_layers: configs.clip_l.num_hidden_layers + 1, ..configs.clip_l.clone() };
    let mut clip_l_requests =
        requests(RANDOM_SEEDS.clip_l, &|c| ClipTextModel::load(ctx, clip_l.clone(), c, false).map(drop))?;
    let h = configs.clip_l.hidden_size;
    clip_l_requests.extend(["weight", "bias"].map(|k| (format!("text_model.final_layer_norm.{k}"), vec![h])));
    add_part(&mut stored, RANDOM_SEEDS.clip_l, TextEncoderSlot::ClipL.single_file_prefix(), None, clip_l_requests);
    let big_g = requests(RANDOM_SEEDS.big_g, &|c| ClipTextModel::load(ctx, configs.big_g.clone(), c, true).map(drop))?;
    let names = open_clip_names(configs.big_g.num_hidden_layers);
    add_part(&mut stored, RANDOM_SEEDS.big_g, TextEncoderSlot::BigG.single_file_prefix(), Some(&names), big_g);
    // OpenCLIP's learnt temperature, ln 100: unused for text, present in the layout.
    let logit_scale = format!("{}logit_scale", TextEncoderSlot::BigG.single_file_prefix());
    stored.push(Stored { name: logit_scale, shape: vec![], transposed: false, parts: vec![], constant: 100f32.ln() });
    let unet = requests(RANDOM_SEEDS.unet, &|c| UNet::load(&configs.unet, c).map(drop))?;
    add_part(&mut stored, RANDOM_SEEDS.unet, "model.diffusion_model.", Some(&unet_names(&configs.unet)?), unet);
    let vae = requests(RANDOM_SEEDS.vae, &|c| AutoencoderKl::load(ctx, configs.vae.clone(), c).map(drop))?;
    add_part(&mut stored, RANDOM_SEEDS.vae, "first_stage_model.", Some(&vae_names(&configs.vae)), vae);
    stored.sort_by(|a, b| a.name.cmp(&b.name));
    let shapes: Vec<(&str, &[usize])> = stored.iter().map(|s| (s.name.as_str(), s.shape.as_slice())).collect();
    let metadata = BTreeMap::from([("vkdiff".to_string(), "random weights of the benchmarks".to_string())]);
    vkdiff_formats::write_safetensors_f16_streamed(path, &shapes, &metadata, &mut |i| values_of(&stored[i]))?;
    Ok(std::fs::metadata(path).map(|m| m.len()).unwrap_or(0))
}

/// Adds one network's requested tensors, renamed by `names` (plain where None) under `prefix`.
fn add_part(
    stored: &mut Vec<Stored>,
    seed: u64,
    prefix: &str,
    names: Option<&OriginalNames>,
    requests: Vec<(String, Vec<usize>)>,
) {
    for (name, shape) in requests {
        let at = match names {
            Some(names) => names.rename(&name).expect("every tensor a network reads has an original name"),
            None => crate::weights::StoredAs::plain(name.clone()),
        };
        let full = format!("{prefix}{}", at.name);
        let mut stored_shape = shape.clone();
        if at.transposed {
            stored_shape.reverse();
        }
        // The original VAE's attention projections are 1×1 convolutions.
        if full.contains(".mid.attn_1.") && stored_shape.len() == 2 {
            stored_shape.extend([1, 1]);
        }
        let block = at.rows.map_or(0, |(part, _)| part);
        // Only a row block of a fused tensor joins one already stored.
        match at.rows.and_then(|_| stored.iter_mut().find(|s| s.name == full)) {
            Some(fused) => {
                fused.shape[0] += shape[0];
                fused.parts.push((block, seed, name, shape));
                fused.parts.sort_by_key(|p| p.0);
            }
            None => stored.push(Stored {
                name: full,
                shape: stored_shape,
                transposed: at.transposed,
                parts: vec![(block, seed, name, shape)],
                constant: 0.0,
            }),
        }
    }
}

/// A stored tensor's values: its parts' random values, transposed where it is stored so.
fn values_of(s: &Stored) -> Vec<f32> {
    if s.parts.is_empty() {
        return vec![s.constant; s.shape.iter().product()];
    }
    let mut out = Vec::with_capacity(s.shape.iter().product());
    for (_, seed, name, shape) in &s.parts {
        let values = Checkpoint::random_values(*seed, name, shape);
        if s.transposed {
            out.extend(transpose(&values, shape[0], shape[1]));
        } else {
            out.extend(values);
        }
    }
    out
}
