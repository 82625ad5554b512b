//! 3×3 convolutions of stride 1 by Winograd's F(2×2, 3×3) (Lavin and Gray, 2015), for the CPU
//! family: each 2×2 block of outputs comes from 16 products of a transformed 4×4 input tile
//! with a transformed filter, where the direct convolution takes 36, so the matrix work is
//! 2.25× smaller. Three steps, each a kernel: the input tiles transformed into 16 planes
//! [16][tiles][Cin], 16 products [tiles × Cin]·[Cin × Cout] on the device's GEMM, and the
//! products transformed back into the output with the convolution's epilogue. The filters are
//! transformed on every call, into [16][Cout][Cin]: keeping them would take 16/9 of every
//! 3×3 filter's memory, and the transform costs a small fraction of the product
//! (docs/benchmark-log.md). The transformed values are stored in the convolution's dtype;
//! F(2, 3)'s transforms add, subtract and halve, so they grow values at most 4×.

use super::bands::{bands, elem};
use super::conv::ConvParams;
use super::gemm::{matmul, Matmul};
use super::{dispatch_flat, element_groups, kernel, u};
use crate::error::Result;
use crate::kernel_choice::probe::ProbeChoice;
use crate::recorder::Recorder;
use crate::tensor::{dtype_size, Dtype, Tensor};

/// The most bytes a band's planes (and its products) take: bands of a large image's tiles
/// rather than one binding's worth, so the scratch stays small beside the activations.
const BAND_BYTES: u64 = 32 << 20;

/// The most scratch memory Winograd's convolutions of at most `channels` channels in and out,
/// over at most `tiles` tiles (2×2 outputs each), hold at once in one recording: the filters,
/// a band's planes and its products, each twice over, as its arena keeps the buffers of the
/// smaller convolutions before the largest: none where such filters are too small to take it.
/// Memory plans add it on every device.
pub fn winograd_scratch_bytes(channels: usize, tiles: usize, dtype: Dtype) -> u64 {
    if 9 * channels * channels < super::SMALL_WEIGHTS {
        return 0;
    }
    let e = dtype_size(dtype) as u64;
    let (channels, tiles) = (channels as u64, tiles as u64);
    let planes = (16 * tiles * channels * e).min(BAND_BYTES);
    2 * (16 * channels * channels * e + 2 * planes)
}

/// Whether `conv2d` takes this path for filter `w` [Cout, KH, KW, Cin] with `p`: the CPU family
/// (`Choices::winograd_from`) where VK_NV_cooperative_matrix2's convolution is not asked for,
/// filters of that many weights or more, 3×3 of stride 1, channels on the vec4 grid.
pub(super) fn applies(rec: &Recorder, w: &Tensor, p: &ConvParams) -> bool {
    let (s, choices) = (w.shape(), rec.context().choices());
    choices.winograd_from.is_some_and(|from| w.numel() >= from)
        && choices.conv != ProbeChoice::Matrix2
        && s.len() == 4
        && s[1] == 3
        && s[2] == 3
        && p.stride == 1
        && s[0].is_multiple_of(4)
        && s[3].is_multiple_of(4)
}

/// out[B, Ho, Wo, Cout] (+)= conv3×3(x[B, H, W, Cin], w[Cout, 3, 3, Cin]) (+ bias) (ReLU), x and
/// out each within one binding. The tiles run in bands whose 16 planes fit one binding and
/// [`BAND_BYTES`]; each
/// tile's sums are the same in any band, so banded and whole runs agree exactly. Returns false,
/// having recorded nothing, where the transformed filters or one tile's planes would pass the
/// binding limit.
pub(super) fn conv2d_winograd(
    rec: &mut Recorder,
    x: &Tensor,
    w: &Tensor,
    bias: Option<&Tensor>,
    out: &Tensor,
    p: &ConvParams,
) -> Result<bool> {
    let [b, h, wd, cin] = [x.shape()[0], x.shape()[1], x.shape()[2], x.shape()[3]];
    let [ho, wo, cout] = [out.shape()[1], out.shape()[2], out.shape()[3]];
    let (tiles_h, tiles_w) = (ho.div_ceil(2), wo.div_ceil(2));
    let limit = rec.context().choices().binding_limit;
    if 16 * cout * cin * elem(w) > limit as usize {
        return Ok(false);
    }
    let per = limit.min(BAND_BYTES) as usize / (16 * cin.max(cout) * elem(x));
    if per == 0 {
        return Ok(false);
    }
    let tiles = b * tiles_h * tiles_w;
    let per = per.min(tiles);
    let (dtype, scratch, ctx) = (x.dtype(), rec.scratch(), rec.context().clone());
    let filters = scratch.tensor(&[16, cout, cin], dtype)?;
    let planes = scratch.tensor(&[16, per, cin], dtype)?;
    let products = scratch.tensor(&[16, per, cout], dtype)?;
    let n = cout * cin / 4;
    let transform = kernel(&ctx, "winograd_weights", dtype, &[], 2)?;
    dispatch_flat(rec, &transform, &[w], &[&filters], &[u(n), u(cin / 4)], element_groups(n))?;
    let input = kernel(&ctx, "winograd_input", dtype, &[], 2)?;
    let output = kernel(&ctx, "winograd_output", dtype, &[], 3)?;
    let flags = bias.is_some() as u32 | (p.accumulate as u32) << 1 | (p.relu as u32) << 2;
    let grid = [u(tiles_h), u(tiles_w)];
    for band in bands(tiles, per) {
        let (count, t0) = (band.len(), u(band.start));
        let n = count * cin / 4;
        let push = [&[u(n), u(h), u(wd), u(cin / 4)][..], &grid, &[t0, u(p.pad.top), u(p.pad.left), u(n)]].concat();
        dispatch_flat(rec, &input, &[x], &[&planes], &push, element_groups(n))?;
        let product = Matmul {
            batch: 16,
            a_batch: count * cin,
            b_batch: cout * cin,
            c_batch: count * cout,
            ..Matmul::dense(count, cout, cin, true)
        };
        matmul(rec, &planes, &filters, None, &products, &product)?;
        let n = count * cout / 4;
        let push = [&[u(n), u(ho), u(wo), u(cout / 4)][..], &grid, &[t0, flags, u(n)]].concat();
        dispatch_flat(rec, &output, &[&products, bias.unwrap_or(out)], &[out], &push, element_groups(n))?;
    }
    Ok(true)
}
