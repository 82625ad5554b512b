//! `VK_NV_cooperative_matrix2`'s probe of a linear layer's product (`bench kernels`,
//! `VKDIFF_LINEAR=cm2`) against an f64 reference on every tile the device runs; Mesa 26.1's
//! lavapipe runs its subgroup-scope tiles through flexible dimensions.

use vkdiff_runtime::ops::{linear_cm2, matmul, Matmul};
use vkdiff_runtime::{built_matrix2_tiles, Context, Dtype, Matrix2Probe, Matrix2Tile, ProbeChoice, Recorder};
use vkdiff_testkit::*;

/// alpha · a[i] · w[i]ᵀ + bias (+ prior) for each batch entry i of `s` (dense: B stored N×K, the
/// batch strides whole matrices), and the sums of the terms' magnitudes that bound its rounding.
fn reference(a: &[f32], w: &[f32], bias: &[f32], prior: &[f32], s: &Matmul) -> (Vec<f64>, Vec<f64>) {
    let (m, n, k) = (s.m, s.n, s.k);
    let (mut out, mut mags) = (vec![0.0; s.batch * m * n], vec![0.0; s.batch * m * n]);
    for i in 0..s.batch {
        for r in 0..m {
            for c in 0..n {
                let at = i * m * n + r * n + c;
                let before = if s.accumulate { prior[at] as f64 } else { 0.0 };
                let (mut sum, mut mag) = (0.0f64, 0.0f64);
                for d in 0..k {
                    let p = a[i * m * k + r * k + d] as f64 * w[i * s.b_batch + c * k + d] as f64;
                    sum += p;
                    mag += p.abs();
                }
                out[at] = s.alpha as f64 * sum + bias[c] as f64 + before;
                mags[at] = s.alpha.abs() as f64 * mag + (bias[c] as f64).abs() + before.abs();
            }
        }
    }
    (out, mags)
}

/// Runs `s` through `ops::matmul` on `ctx` (or, with `direct`, `linear_cm2` on `tile`), with a
/// bias, over random f16 operands, compares, and returns the kernels that ran.
fn check(ctx: &Context, tile: &Matrix2Tile, s: &Matmul, direct: bool, seed: u64) -> Vec<&'static str> {
    let (m, n, k) = (s.m, s.n, s.k);
    let a = stored(&random(s.batch * m * k, seed), Dtype::F16);
    let w = stored(&random((s.batch - 1) * s.b_batch + n * k, seed + 1), Dtype::F16);
    let bias = stored(&random(n, seed + 2), Dtype::F16);
    let prior = stored(&random(s.batch * m * n, seed + 3), Dtype::F16);
    let ta = ctx.upload(&[s.batch * m, k], Dtype::F16, &a).unwrap();
    let tw = ctx.upload(&[w.len() / k, k], Dtype::F16, &w).unwrap();
    let tb = ctx.upload(&[n], Dtype::F16, &bias).unwrap();
    let out = ctx.upload(&[s.batch * m, n], Dtype::F16, &prior).unwrap();
    let ran = ctx
        .run_listing(|rec| match direct {
            true => linear_cm2(rec, [&ta, &tw, &out], Some(&tb), tile),
            false => matmul(rec, &ta, &tw, Some(&tb), &out, s),
        })
        .unwrap();
    let (want, mags) = reference(&a, &w, &bias, &prior, s);
    let what = format!("{} {m}×{n}×{k}, batch {}, accumulate {}", tile.label(), s.batch, s.accumulate);
    let rtol = storage_rtol(Dtype::F16);
    assert_within(&what, &out.download().unwrap(), &want, |i| 1e-6 + 1e-5 * mags[i] + rtol * want[i].abs());
    ran.iter().map(|v| v.kernel).collect()
}

#[test]
fn linear_cm2_multiplies_on_every_tile_the_device_runs() {
    let ctx = ctx();
    let tiles: Vec<_> = ctx.info().matrix2_tiles().into_iter().filter(|t| t.probe == Matrix2Probe::Linear).collect();
    let lavapipe_26 = ctx.info().lavapipe_mesa.is_some_and(|v| v >= (26, 1));
    assert!(
        !(tiles.is_empty() && expect_cooperative() && lavapipe_26),
        "VKDIFF_EXPECT_COOPERATIVE=1 on Mesa 26.1's lavapipe, whose flexible dimensions run the probe: {tiles:?}"
    );
    if tiles.is_empty() {
        let tile = built_matrix2_tiles(Matrix2Probe::Linear)[0];
        let (a, w) = (
            ctx.zeros(&[tile.m as usize, 32], Dtype::F16).unwrap(),
            ctx.zeros(&[tile.n as usize, 32], Dtype::F16).unwrap(),
        );
        let out = ctx.zeros(&[tile.m as usize, tile.n as usize], Dtype::F16).unwrap();
        let mut rec = Recorder::new(&ctx, false).unwrap();
        let err = linear_cm2(&mut rec, [&a, &w, &out], None, &tile).unwrap_err().to_string();
        assert!(err.contains("does not run the VK_NV_cooperative_matrix2 tile"), "{err}");
        return;
    }
    // A context whose binding limit no tensor below fits.
    let limited = private_ctx();
    limited.choose(|c| c.binding_limit = 256);
    for tile in tiles {
        let (m, n, k) = (2 * tile.m as usize, 3 * tile.n as usize, 4 * tile.k as usize);
        check(&ctx, &tile, &Matmul::dense(m, n, k, true), true, 17);
        // K off the tile's steps is refused before anything is recorded.
        let short = ctx.zeros(&[m, k - 8], Dtype::F16).unwrap();
        let w_short = ctx.zeros(&[n, k - 8], Dtype::F16).unwrap();
        let out = ctx.zeros(&[m, n], Dtype::F16).unwrap();
        let mut rec = Recorder::new(&ctx, false).unwrap();
        let err = linear_cm2(&mut rec, [&short, &w_short, &out], None, &tile).unwrap_err().to_string();
        assert!(err.contains("is not a multiple of the tile"), "{err}");
        let f32_out = ctx.zeros(&[m, n], Dtype::F32).unwrap();
        let a = ctx.zeros(&[m, k], Dtype::F16).unwrap();
        let w = ctx.zeros(&[n, k], Dtype::F16).unwrap();
        let err = linear_cm2(&mut rec, [&a, &w, &f32_out], None, &tile).unwrap_err().to_string();
        assert!(err.contains("must be f16"), "{err}");
        // So is a tensor past the binding limit (`ops::matmul` bands such products first).
        let [a, w, out] = [[m, k], [n, k], [m, n]].map(|shape| limited.zeros(&shape, Dtype::F16).unwrap());
        let mut rec = Recorder::new(&limited, false).unwrap();
        let err = linear_cm2(&mut rec, [&a, &w, &out], None, &tile).unwrap_err().to_string();
        assert!(err.contains("past the binding limit"), "{err}");
    }
}

#[test]
fn matmul_takes_the_probe_where_the_context_asks_and_the_tile_fits() {
    // A context of its own: the setting would reach other tests' products in a shared one.
    let ctx = private_ctx();
    let offered = ctx.info().matrix2_tiles().into_iter().find(|t| t.probe == Matrix2Probe::Linear);
    let tile = offered.unwrap_or(built_matrix2_tiles(Matrix2Probe::Linear)[0]);
    let (m, n, k) = (tile.m as usize, 2 * tile.n as usize, 2 * tile.k as usize);
    // Two products in a batch, each its own weight, alpha and a residual; then one whose N is off
    // the tile, which keeps the family's kernel.
    let batched = Matmul { batch: 2, b_batch: n * k, alpha: 0.5, accumulate: true, ..Matmul::dense(m, n, k, true) };
    let off = Matmul::dense(m, n + 8, k, true);
    for (s, fits) in [(batched, true), (off, false)] {
        for kernel in [ProbeChoice::Matrix2, ProbeChoice::Auto] {
            ctx.choose(|c| c.linear = kernel);
            let ran = check(&ctx, &tile, &s, false, 61);
            let due = offered.is_some() && fits && kernel == ProbeChoice::Matrix2;
            assert_eq!(ran.contains(&"gemm_cm2"), due, "{kernel:?}, {}×{}×{}: {ran:?}", s.m, s.n, s.k);
        }
    }
}
