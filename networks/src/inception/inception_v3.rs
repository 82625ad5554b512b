//! The InceptionV3 that FID and KID are defined with (TensorFlow's 2015-12-05 graph, as
//! torch-fidelity's `FeatureExtractorInceptionV3` runs it): TF 1.x bilinear resize to 299²,
//! (x − 128)/128, the network, and the 2048 pooled features. Each `BasicConv2d` is one
//! convolution with its batch norm folded in and ReLU fused into the store.

use crate::error::{Error, Result};
use crate::inception::architecture::{architecture, BranchSpec, ConvSpec, Stage};
use crate::layers::nn::Graph;
use vkdiff_runtime::ops::{self, oihw_to_ohwi, ConvParams, Padding, Pool};
use vkdiff_runtime::{Context, Dtype, Tensor};

/// The side the images are resized to.
pub const INCEPTION_SIZE: usize = 299;
/// Width of the pooled features FID and KID use.
pub const INCEPTION_FEATURES: usize = 2048;
/// RGB input padded with a zero channel (and the first convolution with zero weights for it), so
/// every convolution takes the vectorised kernels, which need channels in fours.
const RGB_PADDED: usize = 4;
/// `nn.BatchNorm2d(eps=0.001)` in every `BasicConv2d`.
const BN_EPS: f64 = 1e-3;

/// Where the loader finds tensors by torch name, as f32 values with their shape.
pub trait TensorSource {
    fn values(&self, name: &str) -> Result<(Vec<usize>, Vec<f32>)>;
}

impl TensorSource for vkdiff_formats::SafeTensors {
    fn values(&self, name: &str) -> Result<(Vec<usize>, Vec<f32>)> {
        Ok(vkdiff_formats::SafeTensors::values(self, name)?)
    }
}

impl TensorSource for vkdiff_formats::TorchPth {
    fn values(&self, name: &str) -> Result<(Vec<usize>, Vec<f32>)> {
        Ok(vkdiff_formats::TorchPth::values(self, name)?)
    }
}

/// One image: RGB bytes, row-major, `height` × `width` × 3.
pub struct RgbPixels<'a> {
    pub data: &'a [u8],
    pub width: usize,
    pub height: usize,
}

/// `BasicConv2d`: conv (no bias) → BatchNorm → ReLU, as one convolution with a bias.
struct BasicConv {
    weight: Tensor,
    bias: Tensor,
    spec: ConvSpec,
}

impl BasicConv {
    fn load(ctx: &Context, dtype: Dtype, src: &dyn TensorSource, name: &str, spec: ConvSpec) -> Result<BasicConv> {
        let [kh, kw] = spec.kernel;
        let w = expect(src, &format!("{name}.conv.weight"), &[spec.cout, spec.cin, kh, kw])?;
        let bn = |p: &str| expect(src, &format!("{name}.bn.{p}"), &[spec.cout]);
        let (gamma, beta, mean, var) = (bn("weight")?, bn("bias")?, bn("running_mean")?, bn("running_var")?);
        let per_out = spec.cin * kh * kw;
        let mut folded = vec![0.0f32; w.len()];
        let mut bias = vec![0.0f32; spec.cout];
        for o in 0..spec.cout {
            let scale = gamma[o] as f64 / (var[o] as f64 + BN_EPS).sqrt();
            for (f, &v) in folded[o * per_out..][..per_out].iter_mut().zip(&w[o * per_out..][..per_out]) {
                *f = (v as f64 * scale) as f32;
            }
            bias[o] = (beta[o] as f64 - mean[o] as f64 * scale) as f32;
        }
        let mut ohwi = oihw_to_ohwi(&folded, spec.cout, spec.cin, kh, kw);
        let cin = if spec.cin == 3 { RGB_PADDED } else { spec.cin };
        if cin != spec.cin {
            ohwi = ohwi
                .chunks(spec.cin)
                .flat_map(|tap| tap.iter().copied().chain(std::iter::repeat_n(0.0, cin - spec.cin)))
                .collect();
        }
        Ok(BasicConv {
            weight: ctx.upload(&[spec.cout, kh, kw, cin], dtype, &ohwi)?,
            bias: ctx.upload(&[spec.cout], dtype, &bias)?,
            spec,
        })
    }

    fn forward(&self, g: &mut Graph, x: &Tensor) -> Result<Tensor> {
        let s = &self.spec;
        let [b, h, w] = [x.shape()[0], x.shape()[1], x.shape()[2]];
        let size = |n: usize, k: usize, p: usize| (n + 2 * p).checked_sub(k).map(|v| v / s.stride + 1);
        let (Some(ho), Some(wo)) = (size(h, s.kernel[0], s.pad[0]), size(w, s.kernel[1], s.pad[1])) else {
            return Err(Error::Config(format!(
                "Inception: a {h}×{w} activation is smaller than a {:?} kernel",
                s.kernel
            )));
        };
        let out = g.alloc(&[b, ho, wo, s.cout])?;
        let pad = Padding { top: s.pad[0], bottom: s.pad[0], left: s.pad[1], right: s.pad[1] };
        let params = ConvParams { stride: s.stride, pad, accumulate: false, relu: true };
        ops::conv2d(&mut g.rec, x, &self.weight, Some(&self.bias), &out, &params)?;
        Ok(out)
    }
}

/// One branch of an Inception block: an optional pooling, a chain of convolutions, and
/// optionally two convolutions applied side by side to the chain's output (InceptionE).
struct Branch {
    pool: Option<Pool>,
    chain: Vec<BasicConv>,
    split: Vec<BasicConv>,
}

impl Branch {
    /// The branch's outputs on `x`: one tensor, or two side by side.
    fn forward(&self, g: &mut Graph, x: &Tensor) -> Result<Vec<Tensor>> {
        let mut y = match &self.pool {
            Some(p) => pool(g, x, p)?,
            None => x.clone(),
        };
        for conv in &self.chain {
            y = conv.forward(g, &y)?;
        }
        if self.split.is_empty() {
            return Ok(vec![y]);
        }
        self.split.iter().map(|c| c.forward(g, &y)).collect()
    }
}

enum Layer {
    Conv(BasicConv),
    Pool(Pool),
    Block(Vec<Branch>),
}

/// torch-fidelity's FID InceptionV3 on the device, up to the 2048 pooled features.
pub struct InceptionV3 {
    ctx: Context,
    dtype: Dtype,
    layers: Vec<Layer>,
}

impl InceptionV3 {
    /// Builds the network from tensors named as in torch-fidelity's
    /// `weights-inception-2015-12-05-6726825d.pth` (pytorch-fid's `pt_inception-…` uses the same
    /// torchvision names). `fc` and `num_batches_tracked` are not needed for the pooled features.
    pub fn load(ctx: &Context, dtype: Dtype, src: &dyn TensorSource) -> Result<InceptionV3> {
        let mut layers = Vec::new();
        for (name, stage) in architecture() {
            layers.push(match stage {
                Stage::Conv(spec) => Layer::Conv(BasicConv::load(ctx, dtype, src, &name, spec)?),
                Stage::Pool(p) => Layer::Pool(p),
                Stage::Block(branches) => {
                    let load = |b: &BranchSpec| -> Result<Branch> {
                        let convs = |list: &[(String, ConvSpec)]| {
                            list.iter()
                                .map(|(n, s)| BasicConv::load(ctx, dtype, src, &format!("{name}.{n}"), *s))
                                .collect::<Result<Vec<_>>>()
                        };
                        Ok(Branch { pool: b.pool, chain: convs(&b.chain)?, split: convs(&b.split)? })
                    };
                    Layer::Block(branches.iter().map(load).collect::<Result<_>>()?)
                }
            });
        }
        Ok(InceptionV3 { ctx: ctx.clone(), dtype, layers })
    }

    /// The 2048 pooled features of each image, [images × 2048] row-major, computed in one batch.
    pub fn features(&self, images: &[RgbPixels]) -> Result<Vec<f32>> {
        if images.is_empty() {
            return Ok(Vec::new());
        }
        let mut g = Graph::new(&self.ctx, self.dtype)?;
        let x = g.alloc(&[images.len(), INCEPTION_SIZE, INCEPTION_SIZE, RGB_PADDED])?;
        for (slot, img) in images.iter().enumerate() {
            if img.width == 0 || img.height == 0 || img.data.len() != img.width * img.height * 3 {
                return Err(Error::Config(format!(
                    "image {slot}: {} bytes for {}×{} RGB",
                    img.data.len(),
                    img.width,
                    img.height
                )));
            }
            let bytes = ops::upload_image_bytes(&self.ctx, img.data)?;
            ops::resize_tf1(&mut g.rec, &bytes, [img.height, img.width, 3], &x, slot, -128.0, 1.0 / 128.0)?;
        }
        let mut x = x;
        for layer in &self.layers {
            x = match layer {
                Layer::Conv(c) => c.forward(&mut g, &x)?,
                Layer::Pool(p) => pool(&mut g, &x, p)?,
                Layer::Block(branches) => {
                    let mut parts = Vec::new();
                    for b in branches {
                        parts.extend(b.forward(&mut g, &x)?);
                    }
                    concat(&mut g, &parts)?
                }
            };
        }
        let pooled = pool(&mut g, &x, &Pool::global_average(x.shape()[1], x.shape()[2]))?;
        g.rec.finish()?.run()?;
        Ok(pooled.download()?)
    }
}

fn pool(g: &mut Graph, x: &Tensor, p: &Pool) -> Result<Tensor> {
    let [h, w] = p
        .output_size(x.shape()[1], x.shape()[2])
        .ok_or_else(|| Error::Config(format!("Inception: {:?} smaller than a pooling window", x.shape())))?;
    let out = g.alloc(&[x.shape()[0], h, w, x.shape()[3]])?;
    ops::pool2d(&mut g.rec, x, &out, p)?;
    Ok(out)
}

/// The branches' outputs side by side along channels, each written into its slice.
fn concat(g: &mut Graph, parts: &[Tensor]) -> Result<Tensor> {
    let s = parts[0].shape();
    let out = g.alloc(&[s[0], s[1], s[2], parts.iter().map(|p| p.shape()[3]).sum()])?;
    let mut at = 0;
    for p in parts {
        ops::copy_into_channels(&mut g.rec, p, &out, at)?;
        at += p.shape()[3];
    }
    Ok(out)
}

/// A tensor's values, checked against the shape the architecture needs.
fn expect(src: &dyn TensorSource, name: &str, shape: &[usize]) -> Result<Vec<f32>> {
    let (got, values) = src.values(name)?;
    if got != shape {
        return Err(Error::Checkpoint(format!("tensor `{name}` has shape {got:?}; InceptionV3 needs {shape:?}")));
    }
    Ok(values)
}
