//! Shared helpers: the device, the tiny SDXL fixture, LoRA factors and their CPU reference.

use std::collections::BTreeMap;
use std::path::Path;
use vkdiff_networks::{unet_checkpoint, ClipTextModel, ParamLayout, Parameters, TextEncoderSlot, UNet};
use vkdiff_runtime::Dtype;
pub use vkdiff_testkit::{ctx, random, repo, scratch};

pub struct Nets {
    pub unet: UNet,
    pub clip_l: ClipTextModel,
    pub big_g: ClipTextModel,
}

impl Nets {
    /// UNet, CLIP-L, bigG: the order `Factors::net` indexes.
    pub fn params(&self) -> [&Parameters; 3] {
        [self.unet.parameters(), self.clip_l.parameters(), self.big_g.parameters()]
    }
}

pub fn tiny_sdxl(dtype: Dtype) -> Nets {
    let ctx = ctx();
    let path = vkdiff_testkit::fixture("pipeline/tiny-sdxl");
    let (config, ckpt) = unet_checkpoint(&ctx, &path, dtype).unwrap();
    let unet = UNet::load(&config, &ckpt).unwrap();
    let clip_l = ClipTextModel::load_sdxl(&ctx, &path, TextEncoderSlot::ClipL, dtype).unwrap();
    let big_g = ClipTextModel::load_sdxl(&ctx, &path, TextEncoderSlot::BigG, dtype).unwrap();
    Nets { unet, clip_l, big_g }
}

/// Every parameter's stored bits.
pub fn snapshot(params: &Parameters) -> BTreeMap<String, Vec<u32>> {
    params
        .names()
        .into_iter()
        .map(|n| {
            (n.to_string(), params.get(n).unwrap().tensor.download().unwrap().iter().map(|v| v.to_bits()).collect())
        })
        .collect()
}

pub fn assert_restored(what: &str, before: &BTreeMap<String, Vec<u32>>, params: &Parameters) {
    let after = snapshot(params);
    for (name, bits) in before {
        assert!(after[name] == *bits, "{what}: `{name}` differs from its original after restore");
    }
}

/// One LoRA module as a test writes it: factors in PyTorch layout, its scale and strength.
#[derive(Clone)]
pub struct Factors {
    /// 0 UNet, 1 CLIP-L, 2 bigG.
    pub net: usize,
    /// The diffusers / transformers weight name it targets.
    pub weight: String,
    pub torch_shape: Vec<usize>,
    pub up: Vec<f32>,
    pub down: Vec<f32>,
    pub rank: usize,
    /// alpha / r as the file encodes it.
    pub scale: f64,
}

impl Factors {
    pub fn new(net: usize, weight: &str, torch_shape: &[usize], rank: usize, scale: f64, seed: u64) -> Factors {
        let (out, fan_in) = (torch_shape[0], torch_shape[1..].iter().product::<usize>());
        let up = random(out * rank, seed).iter().map(|v| 0.2 * v).collect();
        let down = random(rank * fan_in, seed + 1).iter().map(|v| 0.2 * v).collect();
        Factors { net, weight: weight.into(), torch_shape: torch_shape.to_vec(), up, down, rank, scale }
    }

    pub fn down_shape(&self) -> Vec<usize> {
        let mut s = vec![self.rank];
        s.extend(&self.torch_shape[1..]);
        s
    }

    /// [out, r] for a linear weight, [out, r, 1, 1] for a conv.
    pub fn up_shape(&self) -> Vec<usize> {
        let mut s = vec![self.torch_shape[0], self.rank];
        s.extend(self.torch_shape[2..].iter().map(|_| 1));
        s
    }
}

/// Expected weights after a merge: originals plus each module's strength · scale · up · down,
/// laid out like the device tensor, with a per-element bound for the run dtype.
pub struct Expected {
    /// (net, weight name) → (values, bound scale).
    pub values: BTreeMap<(usize, String), (Vec<f64>, Vec<f64>)>,
}

impl Expected {
    pub fn new() -> Expected {
        Expected { values: BTreeMap::new() }
    }

    pub fn add(&mut self, params: [&Parameters; 3], f: &Factors, strength: f64) {
        let p = params[f.net].get(&f.weight).unwrap_or_else(|| panic!("no parameter `{}`", f.weight));
        let entry = self.values.entry((f.net, f.weight.clone())).or_insert_with(|| {
            let w: Vec<f64> = p.tensor.download().unwrap().iter().map(|&v| v as f64).collect();
            let n = w.len();
            (w, vec![0.0; n])
        });
        let (out, r, fan_in) = (f.torch_shape[0], f.rank, f.torch_shape[1..].iter().product::<usize>());
        let s = strength * f.scale;
        for o in 0..out {
            for j in 0..fan_in {
                let (mut sum, mut mag) = (0.0, 0.0);
                for k in 0..r {
                    let t = f.up[o * r + k] as f64 * f.down[k * fan_in + j] as f64;
                    sum += t;
                    mag += t.abs();
                }
                let at = device_index(p.layout, &f.torch_shape, o, j);
                entry.0[at] += s * sum;
                entry.1[at] += (s * mag).abs();
            }
        }
    }

    /// Checks every touched weight; `mag` bounds carry factor rounding in f16.
    pub fn check(&self, params: [&Parameters; 3], dtype: Dtype) {
        for ((net, name), (want, mag)) in &self.values {
            let got = params[*net].get(name).unwrap().tensor.download().unwrap();
            for (i, (&g, (&w, &m))) in got.iter().zip(want.iter().zip(mag)).enumerate() {
                let bound = match dtype {
                    Dtype::F32 => 1e-6 + 1e-6 * w.abs() + 1e-6 * m,
                    Dtype::F16 => 1e-5 + 1e-3 * w.abs() + 2e-3 * m,
                };
                assert!(
                    (g as f64 - w).abs() <= bound,
                    "net {net} {name} ({dtype:?}) element {i}: got {g}, want {w} (bound {bound:.2e})"
                );
            }
        }
    }
}

/// Index in the device tensor of PyTorch element [o, j] (j flattening in, kh, kw).
fn device_index(layout: ParamLayout, shape: &[usize], o: usize, j: usize) -> usize {
    match (layout, shape) {
        (ParamLayout::ConvOhwi, &[_, i, kh, kw]) => {
            let (c, y, x) = (j / (kh * kw), j / kw % kh, j % kw);
            o * kh * kw * i + (y * kw + x) * i + c
        }
        (_, _) => o * shape[1..].iter().product::<usize>() + j,
    }
}

/// Writes LoRA tensors (name, shape, values) with optional header metadata.
pub fn write(path: &Path, tensors: &[(String, Vec<usize>, Vec<f32>)], metadata: &[(&str, String)]) {
    let refs: Vec<(&str, &[usize], &[f32])> =
        tensors.iter().map(|(n, s, v)| (n.as_str(), s.as_slice(), v.as_slice())).collect();
    let meta = metadata.iter().map(|(k, v)| (k.to_string(), v.clone())).collect();
    vkdiff_formats::write_safetensors_f32(path, &refs, &meta).unwrap();
}
