//! Convolutions whose channels are off the vec4 grid (RGB in or out: the VAE's last convolution
//! and its encoder's first, ControlNet's hint encoder): input, weight, bias and output are
//! copied with zero channels up to multiples of 4, so the product runs on the vec4 kernels of
//! the device's GEMM family. Zero channels add nothing to any sum, and the extra output
//! channels are left behind. The scalar kernel this replaces ran the VAE's 128 → 3 convolution
//! at 0.1 GFLOP/s of useful work on lavapipe, a fifth of a 512² decode (BENCHMARKS.md).

use super::conv::{conv2d, ConvParams};
use super::copy_heads::{copy_heads, HeadSpan};
use crate::error::{ensure, Result};
use crate::recorder::Recorder;
use crate::tensor::Tensor;

/// conv2d on `x` [B, H, W, Cin], `w` [Cout, KH, KW, Cin], `out` [B, Ho, Wo, Cout] with Cin or
/// Cout not a multiple of 4.
pub(super) fn conv2d_padded(
    rec: &mut Recorder,
    x: &Tensor,
    w: &Tensor,
    bias: Option<&Tensor>,
    out: &Tensor,
    p: &ConvParams,
) -> Result<()> {
    let [b, h, wd, cin] = [x.shape()[0], x.shape()[1], x.shape()[2], x.shape()[3]];
    let [cout, kh, kw, wcin] = [w.shape()[0], w.shape()[1], w.shape()[2], w.shape()[3]];
    let [ob, ho, wo, ocout] = [out.shape()[0], out.shape()[1], out.shape()[2], out.shape()[3]];
    ensure(wcin == cin && ob == b && ocout == cout && bias.is_none_or(|t| t.numel() == cout), || {
        format!(
            "conv2d: input {:?}, weight {:?}, bias {:?} and output {:?} do not match",
            x.shape(),
            w.shape(),
            bias.map(|t| t.shape()),
            out.shape()
        )
    })?;
    let (cin4, cout4) = (cin.next_multiple_of(4), cout.next_multiple_of(4));
    let xp = widen(rec, x, b * h * wd, cin, cin4)?.reshape(&[b, h, wd, cin4])?;
    // The weight's rows widened to Cin4, then Cout4 − Cout zero rows (filters) after them.
    let taps = kh * kw;
    let rows = widen(rec, w, cout * taps, cin, cin4)?;
    let wp = widen(rec, &rows.reshape(&[1, cout * taps * cin4])?, 1, cout * taps * cin4, cout4 * taps * cin4)?
        .reshape(&[cout4, kh, kw, cin4])?;
    let bp = bias.map(|t| widen(rec, t, 1, cout, cout4)).transpose()?;
    if cout4 == cout {
        return conv2d(rec, &xp, &wp, bp.as_ref(), out, p);
    }
    let pixels = b * ho * wo;
    // An accumulating convolution adds to what `out` holds, so the wide output starts from it.
    let wide = if p.accumulate {
        widen(rec, out, pixels, cout, cout4)?
    } else {
        rec.context().zeros(&[pixels, cout4], out.dtype())?
    };
    conv2d(rec, &xp, &wp, bp.as_ref(), &wide.reshape(&[b, ho, wo, cout4])?, p)?;
    copy_heads(rec, &wide, out, row_span(cout4), row_span(cout), 1, pixels, 1)
}

/// `t` seen as `rows` rows of `from` values, copied into a new [rows, to] tensor with zeros in
/// each row's last `to − from` values (`t` itself where `to == from`).
fn widen(rec: &mut Recorder, t: &Tensor, rows: usize, from: usize, to: usize) -> Result<Tensor> {
    if from == to {
        return t.reshape(&[rows, to]);
    }
    let wide = rec.context().zeros(&[rows, to], t.dtype())?;
    copy_heads(rec, t, &wide, row_span(from), row_span(to), 1, rows, 1)?;
    Ok(wide)
}

/// Dense rows of `width` values, as one head each.
fn row_span(width: usize) -> HeadSpan {
    HeadSpan { offset: 0, ld: width, batch: 0, head_dim: width }
}
