//! `VK_NV_cooperative_matrix2`'s probe of attention (kernels/wgsl/attention_cm2.wgsl: the
//! softmax on the extension's row reductions and per-element operations), which `bench kernels`
//! times beside the matrix-unit attention; networks take it only where `VKDIFF_ATTENTION=cm2`
//! asks.

use super::attention::{checked_dtype, push_constants, vec4_aligned, AttentionLayout};
use super::bands::fit;
use super::matrix2_probes::{asked_tile, ensure_offered};
use super::{kernel, u};
use crate::context::Context;
use crate::error::{ensure, Result};
use crate::kernel_choice::matrix2_tile::{Matrix2Probe, Matrix2Tile};
use crate::kernel_choice::probe::ProbeChoice;
use crate::recorder::Recorder;
use crate::tensor::{Dtype, Tensor};

/// Records out = softmax(scale · Q·Kᵀ)·V for every batch and head, as `ops::attention` does, on
/// `tile`, one of the device's attention tiles (`DeviceInfo::matrix2_tiles`): f16 operands,
/// heads of up to the tile's k values, every stride a multiple of 4, within the binding limit.
pub fn attention_cm2(
    rec: &mut Recorder,
    [q, k, v]: [&Tensor; 3],
    out: &Tensor,
    l: &AttentionLayout,
    scale: f32,
    tile: &Matrix2Tile,
) -> Result<()> {
    let ctx = rec.context().clone();
    ensure_offered(&ctx, "attention_cm2", Matrix2Probe::Attention, tile)?;
    let dtype = checked_dtype(rec, "attention_cm2", [q, k, v, out], l)?;
    ensure(dtype == Dtype::F16, || format!("attention_cm2: the operands must be f16, not {dtype:?}"))?;
    ensure(l.head_dim <= tile.k as usize && vec4_aligned(l), || {
        format!("attention_cm2: heads of up to {} values and strides that are multiples of 4, not {l:?}", tile.k)
    })?;
    ensure(fit(&ctx, &[q, k, v, out]), || "attention_cm2: an operand is past the binding limit".to_string())?;
    record(rec, [q, k, v], out, l, scale, tile)
}

/// Records the probe on operands [`attention_cm2`]'s checks (or `ops::attention`'s, with
/// [`chosen_tile`]'s) have passed.
pub(super) fn record(
    rec: &mut Recorder,
    [q, k, v]: [&Tensor; 3],
    out: &Tensor,
    l: &AttentionLayout,
    scale: f32,
    tile: &Matrix2Tile,
) -> Result<()> {
    rec.count_flops(4.0 * (l.batch * l.heads * l.q_tokens) as f64 * (l.kv_tokens * l.head_dim) as f64);
    let probe = kernel(rec.context(), "attention_cm2", Dtype::F16, &tile.params(), 4)?;
    let groups = [u(l.q_tokens.div_ceil(tile.m as usize)), u(l.heads), u(l.batch)];
    rec.dispatch(&probe, &[q, k, v], &[out], &push_constants(l, scale), groups)
}

/// The attention tile `ops::attention` takes for f16 heads of `head_dim` where `choice` asks
/// for this probe (`VKDIFF_ATTENTION=cm2`, or the tuner): the first the device runs that holds
/// them.
pub(super) fn chosen_tile(ctx: &Context, choice: ProbeChoice, dtype: Dtype, head_dim: usize) -> Option<Matrix2Tile> {
    asked_tile(ctx, choice, dtype, Matrix2Probe::Attention, |t| head_dim <= t.k as usize)
}
