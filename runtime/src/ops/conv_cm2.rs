//! `VK_NV_cooperative_matrix2`'s probe of a convolution's implicit GEMM
//! (kernels/wgsl/conv_cm2.wgsl), which `bench kernels` times beside the matrix-unit convolution;
//! no network takes it yet.

use super::bands::fit;
use super::conv::Padding;
use super::linear_cm2::ensure_offered;
use super::{kernel, u};
use crate::error::{ensure, Error, Result};
use crate::matrix2_tile::{Matrix2Probe, Matrix2Tile};
use crate::recorder::Recorder;
use crate::tensor::{Dtype, Tensor};

/// The values in a unit the kernel gathers along the input channels (its UW).
const UNIT: usize = 8;

/// Records `out` [B, Ho, Wo, Cout] (f32) = conv(`x` [B, H, W, Cin], `w` [Cout, KH, KW, Cin]),
/// both f16, with `stride` and zero padding `pad`, on `tile`, one of the device's convolution
/// tiles (`DeviceInfo::matrix2_tiles`): B·Ho·Wo, Cout and KH·KW·Cin must be multiples of the
/// tile's m, n and k, Cin of 8, and every tensor within the binding limit.
pub fn conv2d_cm2(
    rec: &mut Recorder,
    x: &Tensor,
    w: &Tensor,
    out: &Tensor,
    stride: usize,
    pad: Padding,
    tile: &Matrix2Tile,
) -> Result<()> {
    let ctx = rec.context().clone();
    ensure_offered(&ctx, "conv2d_cm2", Matrix2Probe::Conv, tile)?;
    let (&[b, h, wd, cin], &[cout, kh, kw, wcin], &[ob, ho, wo, oc]) = (x.shape(), w.shape(), out.shape()) else {
        return Err(Error::Shape(format!(
            "conv2d_cm2: want NHWC input, OHWI weight and NHWC output, not {:?}, {:?} and {:?}",
            x.shape(),
            w.shape(),
            out.shape()
        )));
    };
    ensure(x.dtype() == Dtype::F16 && w.dtype() == Dtype::F16 && out.dtype() == Dtype::F32, || {
        format!("conv2d_cm2: x and w must be f16 and out f32, not {:?}, {:?}, {:?}", x.dtype(), w.dtype(), out.dtype())
    })?;
    ensure(wcin == cin, || format!("conv2d_cm2: weight {:?} takes {wcin} channels, input has {cin}", w.shape()))?;
    let (tall, wide) = (h + pad.top + pad.bottom, wd + pad.left + pad.right);
    ensure(stride > 0 && tall >= kh && wide >= kw, || "conv2d_cm2: kernel larger than padded input".to_string())?;
    let want = [b, (tall - kh) / stride + 1, (wide - kw) / stride + 1, cout];
    ensure([ob, ho, wo, oc] == want, || format!("conv2d_cm2: output {:?}, expected {want:?}", out.shape()))?;
    let (m, n, k) = (b * ho * wo, cout, kh * kw * cin);
    let fits = m > 0 && m % tile.m as usize == 0 && n % tile.n as usize == 0 && k > 0 && k % tile.k as usize == 0;
    ensure(fits && cin.is_multiple_of(UNIT), || {
        format!(
            "conv2d_cm2: {m} pixels × {n} channels × K {k} with {cin} input channels: not a multiple of the tile {} \
             and of {UNIT} channels",
            tile.label()
        )
    })?;
    ensure(fit(&ctx, &[x, w, out]), || "conv2d_cm2: a tensor is past the binding limit".to_string())?;
    rec.count_flops(2.0 * (m * n * k) as f64);
    let probe = kernel(&ctx, "conv_cm2", Dtype::F16, &tile.params(), 3)?;
    let push = [m, n, k, h, wd, cin, ho, wo, kw, stride, pad.top, pad.left].map(u);
    let groups = [u(n / tile.n as usize), u(m / tile.m as usize), 1];
    rec.dispatch(&probe, &[x, w], &[out], &push, groups)
}
