//! `bench kernels`' rows for `VK_NV_cooperative_matrix2`'s probes: SDXL's linear rows
//! (`ops::linear_cm2`), its 3×3 convolutions (`ops::conv2d_cm2`) and its 64×64 level's self- and
//! cross-attention (`ops::attention_cm2`) on every probe tile the device runs, beside the
//! matrix-unit kernels' rows.

use super::cases::conv_shape;
use super::{rand_tensor, Case, Work};
use vkdiff_runtime::ops::{self, AttentionLayout, ConvParams};
use vkdiff_runtime::{built_matrix2_tiles, Context, Dtype, Matrix2Probe, Recorder, Tensor};

type Record = fn(&mut Recorder, &[Tensor]) -> vkdiff_runtime::Result<()>;

/// The linear probe on built tile I: `Case::record` is a plain function, so one is made per tile.
fn record_linear<const I: usize>(rec: &mut Recorder, t: &[Tensor]) -> vkdiff_runtime::Result<()> {
    ops::linear_cm2(rec, [&t[0], &t[1], &t[2]], None, &built_matrix2_tiles(Matrix2Probe::Linear)[I])
}

/// The convolution probe on built tile I: a 3×3 convolution with its bias, stride 1, padding 1,
/// as the "conv2d 3x3" rows run it.
fn record_conv<const I: usize>(rec: &mut Recorder, t: &[Tensor]) -> vkdiff_runtime::Result<()> {
    let tile = &built_matrix2_tiles(Matrix2Probe::Conv)[I];
    ops::conv2d_cm2(rec, [&t[0], &t[1], &t[3]], Some(&t[2]), &ConvParams::new(1, 1), tile)
}

/// The attention probe on built tile I, over Q and the output [1, queries, heads, d] and K and V
/// [1, keys, heads, d].
fn record_attention<const I: usize>(rec: &mut Recorder, t: &[Tensor]) -> vkdiff_runtime::Result<()> {
    let (&[_, nq, heads, d], &[_, nk, ..]) = (t[0].shape(), t[1].shape()) else {
        unreachable!("the cases below make these shapes")
    };
    let l = AttentionLayout::dense(1, heads, d, nq, nk);
    let tile = &built_matrix2_tiles(Matrix2Probe::Attention)[I];
    ops::attention_cm2(rec, [&t[0], &t[1], &t[2]], &t[3], &l, (d as f32).sqrt().recip(), tile)
}

/// One recorder per built tile, in `built_matrix2_tiles`' order.
const LINEAR: [Record; 4] = [record_linear::<0>, record_linear::<1>, record_linear::<2>, record_linear::<3>];
const CONV: [Record; 4] = [record_conv::<0>, record_conv::<1>, record_conv::<2>, record_conv::<3>];
const ATTENTION: [Record; 3] = [record_attention::<0>, record_attention::<1>, record_attention::<2>];

/// The attention rows: (queries, keys), 10 heads of 64 (the 64×64 level's self- and
/// cross-attention).
const ATTENTION_ROWS: [(usize, usize); 2] = [(4096, 4096), (4096, 77)];

/// The probes' rows: each of `shapes` (M, N, K) on each linear tile the device runs that
/// divides it, each of `convs` (images, side, channels in and out: a 3×3 convolution) on each
/// convolution tile that divides its product, and the attention rows on each attention tile.
pub(super) fn cases(
    ctx: &Context,
    shapes: &[(usize, usize, usize)],
    convs: &[(usize, usize, usize)],
) -> vkdiff_runtime::Result<Vec<Case>> {
    let offered = ctx.info().matrix2_tiles();
    let mut cases = Vec::new();
    let linear = built_matrix2_tiles(Matrix2Probe::Linear);
    for (i, tile) in linear.iter().enumerate().filter(|(_, t)| offered.contains(t)) {
        for &(m, n, k) in shapes {
            if m % tile.m as usize != 0 || n % tile.n as usize != 0 || k % tile.k as usize != 0 {
                continue;
            }
            cases.push(Case {
                name: "linear, cm2 probe",
                shape: format!("M={m} N={n} K={k}, {}", tile.label()),
                work: Work::Flops(2.0 * (m * n * k) as f64),
                gemm: Some((m, n, k)),
                on_gemm_family: false,
                tensors: vec![
                    rand_tensor(ctx, &[m, k], Dtype::F16, 31)?,
                    rand_tensor(ctx, &[n, k], Dtype::F16, 32)?,
                    ctx.zeros(&[m, n], Dtype::F16)?,
                ],
                record: LINEAR[i],
            });
        }
    }
    let conv = built_matrix2_tiles(Matrix2Probe::Conv);
    for (i, tile) in conv.iter().enumerate().filter(|(_, t)| offered.contains(t)) {
        for &(images, side, c) in convs {
            let (m, k) = (images * side * side, 9 * c);
            if m % tile.m as usize != 0 || c % tile.n as usize != 0 || k % tile.k as usize != 0 {
                continue;
            }
            cases.push(Case {
                name: "conv2d 3x3, cm2 probe",
                shape: format!("{}, {}", conv_shape((images, side, c)), tile.label()),
                work: Work::Flops(2.0 * (m * c * k) as f64),
                gemm: None,
                on_gemm_family: false,
                tensors: vec![
                    rand_tensor(ctx, &[images, side, side, c], Dtype::F16, 36)?,
                    rand_tensor(ctx, &[c, 3, 3, c], Dtype::F16, 37)?,
                    rand_tensor(ctx, &[c], Dtype::F16, 38)?,
                    ctx.zeros(&[images, side, side, c], Dtype::F16)?,
                ],
                record: CONV[i],
            });
        }
    }
    let attention = built_matrix2_tiles(Matrix2Probe::Attention);
    for (i, tile) in attention.iter().enumerate().filter(|(_, t)| offered.contains(t)) {
        for &(nq, nk) in &ATTENTION_ROWS {
            let (heads, d) = (10, 64);
            cases.push(Case {
                name: "attention, cm2 probe",
                shape: format!("{nq} x {nk} tokens, {heads} heads x {d}, {}", tile.label()),
                work: Work::Flops(4.0 * (nq * nk * heads * d) as f64),
                gemm: None,
                on_gemm_family: false,
                tensors: vec![
                    rand_tensor(ctx, &[1, nq, heads, d], Dtype::F16, 33)?,
                    rand_tensor(ctx, &[1, nk, heads, d], Dtype::F16, 34)?,
                    rand_tensor(ctx, &[1, nk, heads, d], Dtype::F16, 35)?,
                    ctx.zeros(&[1, nq, heads, d], Dtype::F16)?,
                ],
                record: ATTENTION[i],
            });
        }
    }
    Ok(cases)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_built_tile_has_a_recorder() {
        assert_eq!(LINEAR.len(), built_matrix2_tiles(Matrix2Probe::Linear).len());
        assert_eq!(CONV.len(), built_matrix2_tiles(Matrix2Probe::Conv).len());
        assert_eq!(ATTENTION.len(), built_matrix2_tiles(Matrix2Probe::Attention).len());
    }
}
