//! `VK_NV_cooperative_matrix2`'s probe of a linear layer's product (kernels/wgsl/gemm_cm2.wgsl),
//! which `bench kernels` times beside the matrix-unit GEMM; no network takes it yet.

use super::{kernel, u};
use crate::context::Context;
use crate::error::{ensure, Error, Result};
use crate::matrix2_tile::{Matrix2Probe, Matrix2Tile};
use crate::recorder::Recorder;
use crate::tensor::{Dtype, Tensor};

/// Records `out` [M, N] (f32) = `a` [M, K] · `w` [N, K]ᵀ (f16, `w` as a linear layer's weight)
/// on `tile`, one of the device's `DeviceInfo::matrix2_tiles`; M, N and K must be multiples of
/// the tile's m, n and k.
pub fn linear_cm2(rec: &mut Recorder, a: &Tensor, w: &Tensor, out: &Tensor, tile: &Matrix2Tile) -> Result<()> {
    let ctx = rec.context().clone();
    ensure_offered(&ctx, "linear_cm2", Matrix2Probe::Linear, tile)?;
    let (&[m, k], &[n, kw], &[mo, no]) = (a.shape(), w.shape(), out.shape()) else {
        return Err(Error::Shape(format!(
            "linear_cm2: a {:?}, w {:?} and out {:?} must be matrices",
            a.shape(),
            w.shape(),
            out.shape()
        )));
    };
    ensure(a.dtype() == Dtype::F16 && w.dtype() == Dtype::F16 && out.dtype() == Dtype::F32, || {
        format!("linear_cm2: a and w must be f16 and out f32, not {:?}, {:?}, {:?}", a.dtype(), w.dtype(), out.dtype())
    })?;
    ensure(kw == k && (mo, no) == (m, n), || {
        format!("linear_cm2: a {:?} · w {:?}ᵀ does not give out {:?}", a.shape(), w.shape(), out.shape())
    })?;
    let fits = m > 0 && m % tile.m as usize == 0 && n % tile.n as usize == 0 && k > 0 && k % tile.k as usize == 0;
    ensure(fits, || format!("linear_cm2: {m}×{n}×{k} is not a multiple of the tile {}", tile.label()))?;
    rec.count_flops(2.0 * (m * n * k) as f64);
    let probe = kernel(&ctx, "gemm_cm2", Dtype::F16, &tile.params(), 3)?;
    let groups = [u(n / tile.n as usize), u(m / tile.m as usize), 1];
    rec.dispatch(&probe, &[a, w], &[out], &[u(m), u(n), u(k)], groups)
}

/// An error unless `tile` is one of `probe`'s that the context's device runs.
pub(super) fn ensure_offered(ctx: &Context, op: &str, probe: Matrix2Probe, tile: &Matrix2Tile) -> Result<()> {
    match tile.probe == probe && ctx.info().matrix2_tiles().contains(tile) {
        true => Ok(()),
        false => Err(Error::Shape(format!(
            "{op}: device `{}` does not run the VK_NV_cooperative_matrix2 tile {}",
            ctx.info().name,
            tile.label()
        ))),
    }
}
