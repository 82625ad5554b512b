//! `VK_NV_cooperative_matrix2`'s probe of a convolution's implicit GEMM
//! (kernels/wgsl/conv_cm2.wgsl), which `bench kernels` times beside the matrix-unit convolution;
//! networks take it only where `VKDIFF_CONV=cm2` asks.

use super::bands::fit;
use super::conv::{checked, ConvParams, ConvProduct};
use super::matrix2_probes::{asked_tile, ensure_offered};
use super::{kernel, u};
use crate::context::Context;
use crate::error::{ensure, Result};
use crate::kernel_choice::matrix2_tile::{Matrix2Probe, Matrix2Tile};
use crate::kernel_choice::probe::ProbeChoice;
use crate::recorder::Recorder;
use crate::tensor::{Dtype, Tensor};

/// The values in a unit the kernel gathers along the input channels (its UW).
const UNIT: usize = 8;

/// Records `out` [B, Ho, Wo, Cout] = conv(`x` [B, H, W, Cin], `w` [Cout, KH, KW, Cin]) (+ bias)
/// (+ out) (ReLU), as `ops::conv2d` does, on `tile`, one of the device's convolution tiles
/// (`DeviceInfo::matrix2_tiles`): f16 tensors, B·Ho·Wo, Cout and KH·KW·Cin multiples of the
/// tile's m, n and k, Cin of 8, every tensor within the binding limit.
pub fn conv2d_cm2(
    rec: &mut Recorder,
    [x, w, out]: [&Tensor; 3],
    bias: Option<&Tensor>,
    p: &ConvParams,
    tile: &Matrix2Tile,
) -> Result<()> {
    let ctx = rec.context().clone();
    ensure_offered(&ctx, "conv2d_cm2", Matrix2Probe::Conv, tile)?;
    let c = checked(rec, "conv2d_cm2", [x, w, out], bias, p)?;
    ensure(c.dtype == Dtype::F16, || format!("conv2d_cm2: the tensors must be f16, not {:?}", c.dtype))?;
    ensure(fits(&c, tile), || {
        format!(
            "conv2d_cm2: {} pixels × {} channels × K {} with {} input channels: not a multiple of the tile {} and \
             of {UNIT} channels",
            c.m,
            c.n,
            c.k,
            c.cin,
            tile.label()
        )
    })?;
    ensure(fit(&ctx, &[x, w, out]), || "conv2d_cm2: a tensor is past the binding limit".to_string())?;
    record(rec, [x, w, bias.unwrap_or(out)], out, &c, tile)
}

/// Whether `tile` takes the convolution `c`.
fn fits(c: &ConvProduct, tile: &Matrix2Tile) -> bool {
    let (m, n, k) = (tile.m as usize, tile.n as usize, tile.k as usize);
    let divides = c.m.is_multiple_of(m) && c.n.is_multiple_of(n) && c.k.is_multiple_of(k);
    c.m > 0 && c.k > 0 && divides && c.cin.is_multiple_of(UNIT)
}

/// Records the probe on a convolution `ops::conv2d`'s checks have passed: `operands` the input,
/// the weight and the bias (or `out`, which stands in for none).
pub(super) fn record(
    rec: &mut Recorder,
    operands: [&Tensor; 3],
    out: &Tensor,
    c: &ConvProduct,
    tile: &Matrix2Tile,
) -> Result<()> {
    rec.count_flops(2.0 * (c.m * c.n * c.k) as f64);
    let probe = kernel(rec.context(), "conv_cm2", Dtype::F16, &tile.params(), 4)?;
    let groups = [u(c.n / tile.n as usize), u(c.m / tile.m as usize), 1];
    rec.dispatch(&probe, &operands, &[out], &c.push, groups)
}

/// The convolution tile `ops::conv2d` takes for `c` where `choice` asks for this probe
/// (`VKDIFF_CONV=cm2`, or the tuner): the first the device runs that takes it.
pub(super) fn chosen_tile(ctx: &Context, choice: ProbeChoice, c: &ConvProduct) -> Option<Matrix2Tile> {
    asked_tile(ctx, choice, c.dtype, Matrix2Probe::Conv, |t| fits(c, t))
}
