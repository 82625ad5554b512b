//! The matrix units' ceiling kernel (`bench kernels`' bound for the cooperative products)
//! against an f64 reference, with its operands in registers and from workgroup memory.

use vkdiff_runtime::ops::{matrix_ceiling, MatrixCeiling};
use vkdiff_runtime::{Dtype, Fragment, Recorder};
use vkdiff_testkit::*;

/// One subgroup's 2×2 sums, Σ over the steps of A_i·B_jᵀ at each step's K offset, and the sums
/// of |a·b| that bound their rounding.
fn reference(operands: &[f32], run: &MatrixCeiling) -> (Vec<f64>, Vec<f64>) {
    let (m, n, k) = (run.fragment.m as usize, run.fragment.n as usize, run.fragment.k as usize);
    // Row r of A (r < 2·FM), then of B (N×K, 2·FN rows), each of 4·FK values.
    let at = |r: usize, c: usize| operands[r * 4 * k + c] as f64;
    let (mut sums, mut mags) = (vec![0.0; 4 * m * n], vec![0.0; 4 * m * n]);
    for step in 0..run.reps as usize {
        let kk = if run.from_shared { (step * run.step as usize % 4) * k } else { 0 };
        for (f, (i, j)) in [(0, 0), (0, 1), (1, 0), (1, 1)].into_iter().enumerate() {
            for r in 0..m {
                for c in 0..n {
                    for d in kk..kk + k {
                        let p = at(i * m + r, d) * at(2 * m + j * n + c, d);
                        sums[f * m * n + r * n + c] += p;
                        mags[f * m * n + r * n + c] += p.abs();
                    }
                }
            }
        }
    }
    (sums, mags)
}

#[test]
fn matrix_ceiling_adds_its_fragment_products() {
    let ctx = ctx();
    let Some(fragment) = ctx.info().cooperative_variant() else {
        let fragment = Fragment { m: 8, n: 8, k: 8, lanes: 8, flexible: false };
        let run = MatrixCeiling { fragment, groups: 1, reps: 1, step: 1, from_shared: false };
        let operands = ctx.zeros(&[run.operand_len()], Dtype::F16).unwrap();
        let sums = ctx.zeros(&[run.sums_len()], Dtype::F32).unwrap();
        let mut rec = Recorder::new(&ctx, false).unwrap();
        let err = matrix_ceiling(&mut rec, &operands, &sums, &run).unwrap_err().to_string();
        assert!(err.contains("has no matrix units vkdiff's kernels fit"), "{err}");
        return;
    };
    // Five steps of stride 3 visit the K offsets 0, 3, 2, 1, 0 (from workgroup memory).
    for from_shared in [false, true] {
        let run = MatrixCeiling { fragment, groups: 3, reps: 5, step: 3, from_shared };
        let values = stored(&random(run.operand_len(), 91), Dtype::F16);
        let operands = ctx.upload(&[run.operand_len()], Dtype::F16, &values).unwrap();
        let sums = ctx.zeros(&[run.sums_len()], Dtype::F32).unwrap();
        ctx.run(|rec| matrix_ceiling(rec, &operands, &sums, &run)).unwrap();
        let (want, mags) = reference(&values, &run);
        let got = sums.download().unwrap();
        // Every workgroup's every subgroup holds the same sums.
        for (s, one) in got.chunks(want.len()).enumerate() {
            assert_within(&format!("ceiling {run:?}, subgroup {s}"), one, &want, |i| 1e-6 * mags[i] + 1e-7);
        }
    }
}
