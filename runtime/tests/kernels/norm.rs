//! GroupNorm (± SiLU), LayerNorm and softmax against f64 references.

use vkdiff_runtime::ops::{group_norm, layer_norm, softmax};
use vkdiff_testkit::*;

// Norm outputs are O(1); f32 two-pass statistics over ≤ 1e5 values keep errors under 1e-5.
const ATOL: f64 = 1e-5;

fn check_group_norm(b: usize, hw: usize, c: usize, groups: usize, silu: bool, seed: u64) {
    // The GPU context splits images into bands of pixels where they hold more than 64.
    for (ctx, dtype) in [ctx(), gpu_ctx()].into_iter().flat_map(|c| DTYPES.map(|d| (c.clone(), d))) {
        let x: Vec<f32> = stored(&random(b * hw * c, seed).iter().map(|v| 3.0 * v + 0.5).collect::<Vec<_>>(), dtype);
        let g = stored(&random(c, seed + 1), dtype);
        let be = stored(&random(c, seed + 2), dtype);
        let tx = ctx.upload(&[b, hw, c], dtype, &x).unwrap();
        let tg = ctx.upload(&[c], dtype, &g).unwrap();
        let tbe = ctx.upload(&[c], dtype, &be).unwrap();
        let out = ctx.zeros(&[b, hw, c], dtype).unwrap();
        ctx.run(|rec| group_norm(rec, &tx, &tg, &tbe, &out, groups, 1e-5, silu)).unwrap();
        let cg = c / groups;
        let mut want = vec![0.0f64; x.len()];
        for n in 0..b {
            for gi in 0..groups {
                let idx = |s: usize, j: usize| (n * hw + s) * c + gi * cg + j;
                let vals: Vec<f64> =
                    (0..hw).flat_map(|s| (0..cg).map(move |j| (s, j))).map(|(s, j)| x[idx(s, j)] as f64).collect();
                let mean = vals.iter().sum::<f64>() / vals.len() as f64;
                let var = vals.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / vals.len() as f64;
                for s in 0..hw {
                    for j in 0..cg {
                        let ch = gi * cg + j;
                        let mut v = (x[idx(s, j)] as f64 - mean) / (var + 1e-5).sqrt() * g[ch] as f64 + be[ch] as f64;
                        if silu {
                            v /= 1.0 + (-v).exp();
                        }
                        want[idx(s, j)] = v;
                    }
                }
            }
        }
        assert_close(
            &format!("group_norm {dtype:?} silu={silu} gpu_paths={}", ctx.choices().gpu_paths),
            &out.download().unwrap(),
            &want,
            ATOL,
            storage_rtol(dtype),
        );
    }
}

#[test]
fn group_norm_plain_and_silu() {
    // Groups of 2, 10, 3 and 16 channels: two a step, one a step, four a step.
    check_group_norm(2, 64, 64, 32, false, 31);
    check_group_norm(1, 37, 320, 32, true, 32);
    check_group_norm(2, 29, 96, 32, true, 34);
    check_group_norm(1, 40, 128, 8, false, 35);
}

#[test]
fn group_norm_in_bands_of_pixels_on_gpus() {
    // 15 bands per image on the GPU context, 14 of 68 pixels and one of 58, merged per image and group.
    check_group_norm(2, 1010, 64, 32, true, 33);
    check_group_norm(1, 1010, 96, 32, false, 36);
    check_group_norm(1, 1010, 128, 32, true, 37);
}

fn check_layer_norm(rows: usize, c: usize, offset: f32, seed: u64) {
    let ctx = ctx();
    for dtype in DTYPES {
        let x = stored(&random(rows * c, seed).iter().map(|v| 2.0 * v + offset).collect::<Vec<_>>(), dtype);
        let g = stored(&random(c, seed + 1), dtype);
        let be = stored(&random(c, seed + 2), dtype);
        let tx = ctx.upload(&[rows, c], dtype, &x).unwrap();
        let tg = ctx.upload(&[c], dtype, &g).unwrap();
        let tbe = ctx.upload(&[c], dtype, &be).unwrap();
        let out = ctx.zeros(&[rows, c], dtype).unwrap();
        ctx.run(|rec| layer_norm(rec, &tx, &tg, &tbe, &out, 1e-5)).unwrap();
        let mut want = vec![0.0; x.len()];
        for r in 0..rows {
            let row = &x[r * c..(r + 1) * c];
            let mean = row.iter().map(|&v| v as f64).sum::<f64>() / c as f64;
            let var = row.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / c as f64;
            for i in 0..c {
                want[r * c + i] = (row[i] as f64 - mean) / (var + 1e-5).sqrt() * g[i] as f64 + be[i] as f64;
            }
        }
        let what = format!("layer_norm {dtype:?} C={c} offset={offset}");
        assert_close(&what, &out.download().unwrap(), &want, ATOL, storage_rtol(dtype));
    }
}

#[test]
fn layer_norm_rows() {
    // C a multiple of 4 (the vec4 kernel, every SDXL and CLIP width) and not.
    check_layer_norm(2 * 77, 320, -0.3, 33);
    check_layer_norm(37, 321, 0.5, 36);
}

#[test]
fn layer_norm_rows_far_from_zero() {
    // Means of 100 over a spread of about 1: a naive E[x²] − E[x]² in f32 would lose the variance.
    check_layer_norm(40, 1280, 100.0, 39);
    check_layer_norm(5, 77, -100.0, 42);
}

#[test]
fn softmax_rows() {
    let ctx = ctx();
    for dtype in DTYPES {
        for (rows, c) in [(10, 77), (3, 1000), (4, 4096)] {
            let x = stored(&random(rows * c, 36).iter().map(|v| 8.0 * v).collect::<Vec<_>>(), dtype);
            let tx = ctx.upload(&[rows, c], dtype, &x).unwrap();
            let out = ctx.zeros(&[rows, c], dtype).unwrap();
            ctx.run(|rec| softmax(rec, &tx, &out, 0.5)).unwrap();
            let mut want = vec![0.0; x.len()];
            for r in 0..rows {
                let row = &x[r * c..(r + 1) * c];
                let m = row.iter().map(|&v| 0.5 * v as f64).fold(f64::MIN, f64::max);
                let s: f64 = row.iter().map(|&v| (0.5 * v as f64 - m).exp()).sum();
                for i in 0..c {
                    want[r * c + i] = (0.5 * row[i] as f64 - m).exp() / s;
                }
            }
            // Probabilities are ≤ 1: 1e-6 absolute, plus storage rounding.
            assert_close(
                &format!("softmax {dtype:?} {rows}x{c}"),
                &out.download().unwrap(),
                &want,
                1e-6,
                storage_rtol(dtype) + 1e-5,
            );
        }
    }
}
