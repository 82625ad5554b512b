//! Inception's spatial operations on NHWC tensors: max and average pooling, and the TensorFlow 1.x
//! bilinear resize its FID weights expect. Pooling past the binding limit goes one image at a time.

use super::bands::{fit, image_rows};
use super::{dispatch_flat, element_groups, f, kernel, same_dtype, u};
use crate::context::Context;
use crate::error::{ensure, Result};
use crate::pipeline::Kernel;
use crate::recorder::Recorder;
use crate::tensor::{Dtype, Tensor};
use std::sync::Arc;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PoolOp {
    /// Padding never wins (PyTorch pads max pooling with −∞).
    Max = 0,
    /// Mean of the taps inside the image (`count_include_pad=False`).
    Average = 1,
}

/// A pooling window: `[height, width]`, stride and symmetric padding.
#[derive(Clone, Copy, Debug)]
pub struct Pool {
    pub op: PoolOp,
    pub window: [usize; 2],
    pub stride: usize,
    pub pad: usize,
}

impl Pool {
    /// The output's [height, width] for an input of `h` × `w`.
    pub fn output_size(&self, h: usize, w: usize) -> Option<[usize; 2]> {
        let size = |n: usize, k: usize| (n + 2 * self.pad).checked_sub(k).map(|s| s / self.stride.max(1) + 1);
        Some([size(h, self.window[0])?, size(w, self.window[1])?])
    }

    /// The global average pooling `AdaptiveAvgPool2d(1)` of an `h` × `w` input.
    pub fn global_average(h: usize, w: usize) -> Pool {
        Pool { op: PoolOp::Average, window: [h, w], stride: 1, pad: 0 }
    }
}

/// out[B, Ho, Wo, C] = pool(x[B, H, W, C]).
pub fn pool2d(rec: &mut Recorder, x: &Tensor, out: &Tensor, pool: &Pool) -> Result<()> {
    let dtype = same_dtype(rec.context(), "pool2d", &[x, out])?;
    let [b, h, w, c] = nhwc(x, "pool2d")?;
    ensure(pool.stride > 0 && pool.pad < pool.window[0].min(pool.window[1]), || {
        format!("pool2d: window {:?} with padding {}", pool.window, pool.pad)
    })?;
    let [ho, wo] = pool
        .output_size(h, w)
        .ok_or_else(|| crate::Error::Shape(format!("pool2d: window {:?} larger than {h}×{w}", pool.window)))?;
    ensure(out.shape() == [b, ho, wo, c], || {
        format!("pool2d: output {:?}, expected {:?}", out.shape(), [b, ho, wo, c])
    })?;
    let k = kernel(rec.context(), "pool2d", dtype, &[("OP", pool.op as u32)], 2)?;
    let push = |n: usize| {
        vec![u(n), u(h), u(w), u(c), u(ho), u(wo), u(pool.window[0]), u(pool.window[1]), u(pool.stride), u(pool.pad)]
    };
    per_image(rec, &k, x, out, push)
}

/// An 8-bit image's bytes (H·W·C, row-major) on the device, four to a 32-bit word, as
/// [`resize_tf1`] reads them.
pub fn upload_image_bytes(ctx: &Context, bytes: &[u8]) -> Result<Tensor> {
    let mut words = bytes.to_vec();
    words.resize(bytes.len().div_ceil(4).max(1) * 4, 0);
    ctx.upload_bytes(&[words.len() / 4], Dtype::F32, &words)
}

/// out[first, Ho, Wo, ..C] = (the 8-bit image (`image`, from [`upload_image_bytes`], of
/// `[H, W, C]`) resized bilinearly as TensorFlow 1.x does it + shift) · scale, and 0 in any further
/// channels of `out`: images of any size resized into their slots of one network batch.
pub fn resize_tf1(
    rec: &mut Recorder,
    image: &Tensor,
    [h, w, c]: [usize; 3],
    out: &Tensor,
    first: usize,
    shift: f32,
    scale: f32,
) -> Result<()> {
    let dtype = same_dtype(rec.context(), "resize", &[out])?;
    let [ob, ho, wo, oc] = nhwc(out, "resize")?;
    ensure(h > 0 && w > 0 && c > 0 && image.bytes() as usize >= h * w * c, || {
        format!("resize: {} bytes for a {h}×{w}×{c} image", image.bytes())
    })?;
    ensure(first < ob && oc >= c, || format!("resize: a {h}×{w}×{c} image into image {first} of {:?}", out.shape()))?;
    ensure(fit(rec.context(), &[image, out]), || {
        format!("resize: a {h}×{w}×{c} image into {:?} passes the binding limit", out.shape())
    })?;
    let k = kernel(rec.context(), "resize_tf1", dtype, &[], 2)?;
    // torch-fidelity: the ratio in double precision, then rounded to float32.
    let ratio = |i: usize, o: usize| (i as f64 / o as f64) as f32;
    let n = ho * wo * oc;
    let push =
        [u(n), u(h), u(w), u(c), u(oc), u(ho), u(wo), f(ratio(h, ho)), f(ratio(w, wo)), f(shift), f(scale), u(first)];
    dispatch_flat(rec, &k, &[image], &[out], &push, element_groups(n))
}

fn nhwc(t: &Tensor, what: &str) -> Result<[usize; 4]> {
    let s = t.shape();
    ensure(s.len() == 4 && s.iter().all(|&d| d > 0), || format!("{what}: want a non-empty NHWC tensor, got {s:?}"))?;
    Ok([s[0], s[1], s[2], s[3]])
}

/// One pooling dispatch over the whole batch, or one per image past the binding limit; `push`
/// takes the number of output elements the dispatch covers.
fn per_image(
    rec: &mut Recorder,
    k: &Arc<Kernel>,
    x: &Tensor,
    out: &Tensor,
    push: impl Fn(usize) -> Vec<u32>,
) -> Result<()> {
    if fit(rec.context(), &[x, out]) {
        return dispatch_flat(rec, k, &[x], &[out], &push(out.numel()), element_groups(out.numel()));
    }
    let (h, ho) = (x.shape()[1], out.shape()[1]);
    for image in 0..x.shape()[0] {
        let (xs, os) = (image_rows(x, image, 0..h)?, image_rows(out, image, 0..ho)?);
        ensure(fit(rec.context(), &[&xs, &os]), || {
            format!("pool2d: one image of {:?} passes the binding limit", x.shape())
        })?;
        dispatch_flat(rec, k, &[&xs], &[&os], &push(os.numel()), element_groups(os.numel()))?;
    }
    Ok(())
}
