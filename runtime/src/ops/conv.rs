//! 2-D convolution on NHWC tensors as an implicit GEMM (no im2col buffer).

use super::bands::{bands, elem, fit, image_rows, rows_per_band};
use super::conv_padded::conv2d_padded;
use super::gemm_family::{dispatch_gemm_family, GemmKernels, GemmShape};
use super::{f, same_dtype, u};
use crate::error::{ensure, Result};
use crate::kernel_choice::tuned::KernelPick;
use crate::kernel_choice::tuning::{name_parts, pick, Tunable};
use crate::recorder::Recorder;
use crate::tensor::{Dtype, Tensor};

/// Zero padding on each side. Symmetric for the UNet; the VAE's downsampler pads only
/// bottom and right.
#[derive(Clone, Copy, Debug)]
pub struct Padding {
    pub top: usize,
    pub left: usize,
    pub bottom: usize,
    pub right: usize,
}

impl Padding {
    pub fn same(p: usize) -> Padding {
        Padding { top: p, left: p, bottom: p, right: p }
    }
}

/// How a convolution walks its input and treats its output.
#[derive(Clone, Copy, Debug)]
pub struct ConvParams {
    pub stride: usize,
    pub pad: Padding,
    /// Adds the result to what `out` holds (a fused residual connection).
    pub accumulate: bool,
    /// max(·, 0) of the result (Inception's conv + folded batch norm + ReLU in one pass).
    pub relu: bool,
}

impl ConvParams {
    /// Stride `stride`, symmetric padding `pad`, output overwritten.
    pub fn new(stride: usize, pad: usize) -> ConvParams {
        ConvParams { stride, pad: Padding::same(pad), accumulate: false, relu: false }
    }
}

/// Re-lays a PyTorch conv weight [out, in, kh, kw] as [out, kh, kw, in], the layout the kernel
/// reads K = (ky·kw + kx)·in + ci from.
pub fn oihw_to_ohwi(w: &[f32], cout: usize, cin: usize, kh: usize, kw: usize) -> Vec<f32> {
    let mut out = vec![0.0; w.len()];
    for o in 0..cout {
        for i in 0..cin {
            for y in 0..kh {
                for x in 0..kw {
                    out[((o * kh + y) * kw + x) * cin + i] = w[((o * cin + i) * kh + y) * kw + x];
                }
            }
        }
    }
    out
}

/// out[B, Ho, Wo, Cout] = conv(x[B, H, W, Cin], w[Cout, KH, KW, Cin]) (+ bias) (+ out) (ReLU), with the
/// output size implied by stride and padding. Input or output past the binding limit is
/// convolved in bands of output rows, each reading its input rows plus the kernel's halo;
/// channels off the vec4 grid are padded onto it (conv_padded.rs).
pub fn conv2d(
    rec: &mut Recorder,
    x: &Tensor,
    w: &Tensor,
    bias: Option<&Tensor>,
    out: &Tensor,
    p: &ConvParams,
) -> Result<()> {
    let four_d = [x, w, out].iter().all(|t| t.shape().len() == 4);
    if four_d && !(x.shape()[3].is_multiple_of(4) && w.shape()[0].is_multiple_of(4)) {
        return conv2d_padded(rec, x, w, bias, out, p);
    }
    if fit(rec.context(), &[x, out]) || !four_d {
        return conv2d_whole(rec, x, w, bias, out, p);
    }
    let [b, h, wd, cin] = [x.shape()[0], x.shape()[1], x.shape()[2], x.shape()[3]];
    let [ho, wo, cout] = [out.shape()[1], out.shape()[2], out.shape()[3]];
    let (kh, kw, s) = (w.shape()[1], w.shape()[2], p.stride.max(1));
    let expect = [
        b,
        (h + p.pad.top + p.pad.bottom).saturating_sub(kh) / s + 1,
        (wd + p.pad.left + p.pad.right).saturating_sub(kw) / s + 1,
        w.shape()[0],
    ];
    ensure(out.shape() == expect, || format!("conv2d: output {:?}, expected {expect:?}", out.shape()))?;
    let ctx = rec.context().clone();
    // Bands of an even number of rows where the binding alignment allows, so Winograd's 2×2 tiles
    // (winograd.rs) fall where the whole image's would.
    let by_out = rows_per_band(&ctx, "conv2d", &[wo * cout * elem(out)], 0, 2)?;
    let by_in = (rows_per_band(&ctx, "conv2d", &[wd * cin * elem(x)], kh, 2)? - 1) / s + 1;
    for image in 0..b {
        for rows in bands(ho, by_out.min(by_in)) {
            // Input rows this band reads, before clipping to the image: the clipped part is padding.
            let first = (rows.start * s) as isize - p.pad.top as isize;
            let end = ((rows.end - 1) * s + kh) as isize - p.pad.top as isize;
            let (lo, hi) = (first.max(0) as usize, (end.min(h as isize)) as usize);
            let pad = Padding { top: (lo as isize - first) as usize, bottom: (end - hi as isize) as usize, ..p.pad };
            let band = ConvParams { pad, ..*p };
            conv2d_whole(rec, &image_rows(x, image, lo..hi)?, w, bias, &image_rows(out, image, rows)?, &band)?;
        }
    }
    Ok(())
}

fn conv2d_whole(
    rec: &mut Recorder,
    x: &Tensor,
    w: &Tensor,
    bias: Option<&Tensor>,
    out: &Tensor,
    p: &ConvParams,
) -> Result<()> {
    let c = checked(rec, "conv2d", [x, w, out], bias, p)?;
    if super::winograd::applies(rec, w, p) && super::winograd::conv2d_winograd(rec, x, w, bias, out, p)? {
        return Ok(());
    }
    let record = |rec: &mut Recorder, pick: KernelPick, reads: &[&Tensor], out: &Tensor| {
        // Without a bias the kernel never reads binding 2; the output stands in for it.
        let operands = [reads[0], reads[1], reads.get(2).copied().unwrap_or(out)];
        if let Some(tile) = super::conv_cm2::chosen_tile(rec.context(), pick.probe, &c) {
            return super::conv_cm2::record(rec, operands, out, &c, &tile);
        }
        let (m, n, k, cin) = (c.m, c.n, c.k, c.cin);
        let shape = GemmShape { m, n, k, batch: 1, vec4: cin % 4 == 0 && n % 4 == 0, vec8: cin % 8 == 0 && n % 4 == 0 };
        let kernels =
            GemmKernels { subgroup: "conv_sg", tiled_v4: "conv_tiled_v4", tiled: None, cooperative: "conv_coop" };
        dispatch_gemm_family(rec, (kernels, c.dtype, &[]), pick.tile, &shape, &operands, out, &c.push)
    };
    let reads: Vec<&Tensor> = [x, w].into_iter().chain(bias).collect();
    let describe = || {
        let (xs, ws) = (x.shape(), w.shape());
        let stride = if p.stride > 1 { format!(", stride {}", p.stride) } else { String::new() };
        let extras = name_parts(&[(bias.is_some(), " + bias"), (p.accumulate, " + residual"), (p.relu, ", ReLU")]);
        let (kernel, input) = (format!("{}×{}", ws[1], ws[2]), format!("{}×{}×{}", xs[1], xs[2], xs[3]));
        Tunable {
            key: format!("conv2d {:?} {:?}", c.push, c.dtype),
            op: format!("conv2d {kernel} {input} → {}{stride}{extras} {:?}", ws[0], c.dtype),
            tiles: true,
        }
    };
    let pick = pick(rec, (&reads, out), rec.context().choices().conv, describe, &record);
    record(rec, pick, &reads, out)
}

/// A convolution as its kernels take it: the product's M (output pixels), N (output channels)
/// and K (taps × input channels), the input's channels, the storage dtype, and the push constants
/// (gemm_common.wgsl's GemmParams, then conv_taps.wgsl's AParams).
pub(super) struct ConvProduct {
    pub m: usize,
    pub n: usize,
    pub k: usize,
    pub cin: usize,
    pub dtype: Dtype,
    pub push: [u32; 18],
}

/// `x` [B, H, W, Cin], `w` [Cout, KH, KW, Cin] and `out` [B, Ho, Wo, Cout] checked against each
/// other, `bias` and `p`, as `op`'s errors name them.
pub(super) fn checked(
    rec: &Recorder,
    op: &str,
    [x, w, out]: [&Tensor; 3],
    bias: Option<&Tensor>,
    p: &ConvParams,
) -> Result<ConvProduct> {
    let (stride, pad) = (p.stride, p.pad);
    let dtype = same_dtype(rec.context(), op, &[x, w, out])?;
    ensure(x.shape().len() == 4 && w.shape().len() == 4 && out.shape().len() == 4, || {
        format!(
            "{op}: want NHWC input, OHWI weight, NHWC output; got {:?}, {:?}, {:?}",
            x.shape(),
            w.shape(),
            out.shape()
        )
    })?;
    let [b, h, wd, cin] = [x.shape()[0], x.shape()[1], x.shape()[2], x.shape()[3]];
    let [cout, kh, kw, wcin] = [w.shape()[0], w.shape()[1], w.shape()[2], w.shape()[3]];
    ensure(wcin == cin, || format!("{op}: weight {:?} takes {wcin} channels, input has {cin}", w.shape()))?;
    ensure(stride > 0 && h + pad.top + pad.bottom >= kh && wd + pad.left + pad.right >= kw, || {
        format!("{op}: kernel larger than padded input")
    })?;
    let ho = (h + pad.top + pad.bottom - kh) / stride + 1;
    let wo = (wd + pad.left + pad.right - kw) / stride + 1;
    ensure(out.shape() == [b, ho, wo, cout], || {
        format!("{op}: output {:?}, expected {:?}", out.shape(), [b, ho, wo, cout])
    })?;
    if let Some(bias) = bias {
        ensure(bias.numel() == cout && bias.dtype() == dtype, || {
            format!("{op}: bias {:?} for {cout} channels", bias.shape())
        })?;
    }
    let (m, n, k) = (b * ho * wo, cout, kh * kw * cin);
    let flags = bias.is_some() as u32 | (p.accumulate as u32) << 1 | (p.relu as u32) << 2;
    let push = [
        u(m),
        u(n),
        u(k),
        u(k),
        u(n),
        0,
        0,
        flags,
        f(1.0),
        u(h),
        u(wd),
        u(cin),
        u(ho),
        u(wo),
        u(kw),
        u(stride),
        u(pad.top),
        u(pad.left),
    ];
    Ok(ConvProduct { m, n, k, cin, dtype, push })
}
