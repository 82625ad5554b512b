//! `VK_NV_cooperative_matrix2`'s probe of a linear layer's product (kernels/wgsl/gemm_cm2.wgsl),
//! which `bench kernels` times beside the matrix-unit GEMM; networks take it only where
//! `VKDIFF_LINEAR=cm2` asks.

use super::bands::fit;
use super::gemm::{push_constants, Matmul};
use super::matrix2_probes::{asked_tile, ensure_offered};
use super::{kernel, u};
use crate::context::Context;
use crate::error::{ensure, Error, Result};
use crate::kernel_choice::matrix2_tile::{Matrix2Probe, Matrix2Tile};
use crate::kernel_choice::probe::ProbeChoice;
use crate::recorder::Recorder;
use crate::tensor::{Dtype, Tensor};

/// Records `out` [M, N] = `a` [M, K] · `w` [N, K]ᵀ (+ bias), as `ops::linear` does, on `tile`, one
/// of the device's linear tiles (`DeviceInfo::matrix2_tiles`): f16 tensors, M, N and K multiples
/// of the tile's m, n and k, K of 8, every tensor within the binding limit (`ops::matmul` bands
/// larger products).
pub fn linear_cm2(
    rec: &mut Recorder,
    [a, w, out]: [&Tensor; 3],
    bias: Option<&Tensor>,
    tile: &Matrix2Tile,
) -> Result<()> {
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
    let f16 = [a, w, out].iter().chain(bias.as_ref()).all(|t| t.dtype() == Dtype::F16);
    ensure(f16, || format!("linear_cm2: the tensors must be f16, not {:?}", [a.dtype(), w.dtype(), out.dtype()]))?;
    ensure(kw == k && (mo, no) == (m, n) && bias.is_none_or(|b| b.numel() == n), || {
        format!(
            "linear_cm2: a {:?} · w {:?}ᵀ does not give out {:?} (bias for each column)",
            a.shape(),
            w.shape(),
            out.shape()
        )
    })?;
    let s = Matmul::dense(m, n, k, true);
    ensure(fits(&s, tile), || format!("linear_cm2: {m}×{n}×{k} is not a multiple of the tile {}", tile.label()))?;
    let operands: Vec<&Tensor> = [a, w, out].into_iter().chain(bias).collect();
    ensure(fit(&ctx, &operands), || "linear_cm2: a tensor is past the binding limit".to_string())?;
    record(rec, [a, w, bias.unwrap_or(out)], out, &s, &push_constants(&s, bias.is_some()), tile)
}

/// Whether `tile` takes the product `s`: B stored N×K, no GEGLU, sizes multiples of the tile's
/// and strides of 8 values.
fn fits(s: &Matmul, tile: &Matrix2Tile) -> bool {
    let (m, n, k) = (tile.m as usize, tile.n as usize, tile.k as usize);
    let strides = [s.lda, s.ldb, s.ldc, s.a_batch, s.b_batch, s.c_batch].iter().all(|x| x.is_multiple_of(8));
    let divides = s.m.is_multiple_of(m) && s.n.is_multiple_of(n) && s.k.is_multiple_of(k);
    s.b_transposed && !s.geglu && s.m > 0 && s.k > 0 && divides && strides
}

/// Records the probe on a product `ops::matmul`'s checks have passed: `operands` A, B and the
/// bias (or C, which stands in for none), `push` its push constants.
pub(super) fn record(
    rec: &mut Recorder,
    operands: [&Tensor; 3],
    c: &Tensor,
    s: &Matmul,
    push: &[u32],
    tile: &Matrix2Tile,
) -> Result<()> {
    rec.count_flops(2.0 * (s.batch * s.m) as f64 * (s.n * s.k) as f64);
    let probe = kernel(rec.context(), "gemm_cm2", Dtype::F16, &tile.params(), 4)?;
    let groups = [u(s.n / tile.n as usize), u(s.m / tile.m as usize), u(s.batch)];
    rec.dispatch(&probe, &operands, &[c], push, groups)
}

/// The linear tile `ops::matmul` takes for `s` where `choice` asks for this probe
/// (`VKDIFF_LINEAR=cm2`, or the tuner): the first the device runs that takes it.
pub(super) fn chosen_tile(ctx: &Context, choice: ProbeChoice, s: &Matmul, dtype: Dtype) -> Option<Matrix2Tile> {
    asked_tile(ctx, choice, dtype, Matrix2Probe::Linear, |t| fits(s, t))
}
