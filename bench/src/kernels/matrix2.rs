//! `bench kernels`' rows for `VK_NV_cooperative_matrix2`'s probe (`ops::linear_cm2`): SDXL's
//! linear rows on every probe tile the device runs, beside the matrix-unit GEMM's rows.

use super::{rand_tensor, Case, Work};
use vkdiff_runtime::{built_matrix2_tiles, ops, Context, Dtype, Recorder, Tensor};

type Record = fn(&mut Recorder, &[Tensor]) -> vkdiff_runtime::Result<()>;

/// The probe on built tile I: `Case::record` is a plain function, so one is made per tile.
fn record_tile<const I: usize>(rec: &mut Recorder, t: &[Tensor]) -> vkdiff_runtime::Result<()> {
    ops::linear_cm2(rec, &t[0], &t[1], &t[2], &built_matrix2_tiles()[I])
}

/// One recorder per built tile, in `built_matrix2_tiles`' order.
const RECORDERS: [Record; 4] = [record_tile::<0>, record_tile::<1>, record_tile::<2>, record_tile::<3>];

/// The probe's rows: each of `shapes` (M, N, K) on each tile the device runs that divides it.
pub(super) fn cases(ctx: &Context, shapes: &[(usize, usize, usize)]) -> vkdiff_runtime::Result<Vec<Case>> {
    let offered = ctx.info().matrix2_tiles();
    let mut cases = Vec::new();
    for (i, tile) in built_matrix2_tiles().iter().enumerate().filter(|(_, t)| offered.contains(t)) {
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
                    ctx.zeros(&[m, n], Dtype::F32)?,
                ],
                record: RECORDERS[i],
            });
        }
    }
    Ok(cases)
}

#[cfg(test)]
mod tests {
    #[test]
    fn every_built_tile_has_a_recorder() {
        assert_eq!(super::RECORDERS.len(), super::built_matrix2_tiles().len());
    }
}
