//! `VK_NV_cooperative_matrix2`'s probe of a linear layer's product (`bench kernels`) against an
//! f64 reference on every tile the device runs; Mesa 26.1's lavapipe runs its subgroup-scope
//! tiles through flexible dimensions.

use vkdiff_runtime::ops::linear_cm2;
use vkdiff_runtime::{built_matrix2_tiles, Dtype, Matrix2Probe, Recorder};
use vkdiff_testkit::*;

/// a [M, K] · w [N, K]ᵀ, and the sums of |a·w| that bound its rounding.
fn reference(a: &[f32], w: &[f32], (m, n, k): (usize, usize, usize)) -> (Vec<f64>, Vec<f64>) {
    let (mut out, mut mags) = (vec![0.0; m * n], vec![0.0; m * n]);
    for r in 0..m {
        for c in 0..n {
            for d in 0..k {
                let p = a[r * k + d] as f64 * w[c * k + d] as f64;
                out[r * n + c] += p;
                mags[r * n + c] += p.abs();
            }
        }
    }
    (out, mags)
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
        let out = ctx.zeros(&[tile.m as usize, tile.n as usize], Dtype::F32).unwrap();
        let mut rec = Recorder::new(&ctx, false).unwrap();
        let err = linear_cm2(&mut rec, &a, &w, &out, &tile).unwrap_err().to_string();
        assert!(err.contains("does not run the VK_NV_cooperative_matrix2 tile"), "{err}");
        return;
    }
    for tile in tiles {
        let (m, n, k) = (2 * tile.m as usize, 3 * tile.n as usize, 4 * tile.k as usize);
        let a_values = stored(&random(m * k, 17), Dtype::F16);
        let w_values = stored(&random(n * k, 29), Dtype::F16);
        let a = ctx.upload(&[m, k], Dtype::F16, &a_values).unwrap();
        let w = ctx.upload(&[n, k], Dtype::F16, &w_values).unwrap();
        let out = ctx.zeros(&[m, n], Dtype::F32).unwrap();
        ctx.run(|rec| linear_cm2(rec, &a, &w, &out, &tile)).unwrap();
        let (want, mags) = reference(&a_values, &w_values, (m, n, k));
        assert_within(&format!("linear_cm2 {}", tile.label()), &out.download().unwrap(), &want, |i| {
            1e-6 * mags[i] + 1e-7
        });
        // K off the tile's steps is refused before anything is recorded.
        let short = ctx.zeros(&[m, k - 8], Dtype::F16).unwrap();
        let w_short = ctx.zeros(&[n, k - 8], Dtype::F16).unwrap();
        let mut rec = Recorder::new(&ctx, false).unwrap();
        let err = linear_cm2(&mut rec, &short, &w_short, &out, &tile).unwrap_err().to_string();
        assert!(err.contains("is not a multiple of the tile"), "{err}");
    }
}
