//! `VK_NV_cooperative_matrix2`'s probe of the convolution (`bench kernels`) against the f64
//! direct convolution on every convolution tile the device runs; Mesa 26.1's lavapipe runs its
//! subgroup-scope tile through flexible dimensions.

use super::conv::{reference, Case};
use vkdiff_runtime::ops::{conv2d, conv2d_cm2, oihw_to_ohwi, ConvParams, Padding};
use vkdiff_runtime::{built_matrix2_tiles, Context, Dtype, Matrix2Probe, Matrix2Tile, ProbeChoice, Recorder};
use vkdiff_testkit::*;

/// A case neither accumulating nor with ReLU (each test adds its bias).
fn case(b: usize, [h, w]: [usize; 2], [cin, cout]: [usize; 2], k: [usize; 2], stride: usize, pad: Padding) -> Case {
    Case { b, h, w, cin, cout, k, stride, pad, accumulate: false, relu: false }
}

/// Runs the probe on `tile` over random f16 input, weight, bias and (where the case
/// accumulates) output, and compares.
fn check(ctx: &Context, tile: &Matrix2Tile, c: &Case, seed: u64) {
    let ([kh, kw], [ho, wo]) = (c.k, c.out_size());
    let x = stored(&random(c.b * c.h * c.w * c.cin, seed), Dtype::F16);
    let w_oihw = stored(&random(c.cout * c.cin * kh * kw, seed + 1), Dtype::F16);
    let bias = stored(&random(c.cout, seed + 2), Dtype::F16);
    let size = c.b * ho * wo * c.cout;
    let prior = if c.accumulate { stored(&random(size, seed + 3), Dtype::F16) } else { vec![0.0; size] };
    let tx = ctx.upload(&[c.b, c.h, c.w, c.cin], Dtype::F16, &x).unwrap();
    let w = oihw_to_ohwi(&w_oihw, c.cout, c.cin, kh, kw);
    let tw = ctx.upload(&[c.cout, kh, kw, c.cin], Dtype::F16, &w).unwrap();
    let tb = ctx.upload(&[c.cout], Dtype::F16, &bias).unwrap();
    let out = ctx.upload(&[c.b, ho, wo, c.cout], Dtype::F16, &prior).unwrap();
    let params = ConvParams { stride: c.stride, pad: c.pad, accumulate: c.accumulate, relu: c.relu };
    ctx.run(|rec| conv2d_cm2(rec, [&tx, &tw, &out], Some(&tb), &params, tile)).unwrap();
    let (want, mag) = reference(c, &x, &w_oihw, &bias, &prior);
    let what = format!(
        "conv2d_cm2 {}: {}x{}x{}x{} -> {} k{:?} s{} {:?} accumulate {} relu {}",
        tile.label(),
        c.b,
        c.h,
        c.w,
        c.cin,
        c.cout,
        c.k,
        c.stride,
        c.pad,
        c.accumulate,
        c.relu
    );
    // f32 accumulation of f16 products (1e-5 of Σ|x·w|, as the convolution tests bound it), then
    // the f16 store's rounding.
    let rtol = storage_rtol(Dtype::F16);
    assert_within(&what, &out.download().unwrap(), &want, |i| 1e-6 + 1e-5 * mag[i] + rtol * want[i].abs());
}

/// The error the probe gives for `c` on `tile`, recording nothing.
fn refusal(ctx: &Context, tile: &Matrix2Tile, c: &Case, dtype: Dtype) -> String {
    let ([kh, kw], [ho, wo]) = (c.k, c.out_size());
    let x = ctx.zeros(&[c.b, c.h, c.w, c.cin], dtype).unwrap();
    let w = ctx.zeros(&[c.cout, kh, kw, c.cin], dtype).unwrap();
    let out = ctx.zeros(&[c.b, ho, wo, c.cout], dtype).unwrap();
    let mut rec = Recorder::new(ctx, false).unwrap();
    let params = ConvParams { stride: c.stride, pad: c.pad, accumulate: false, relu: false };
    conv2d_cm2(&mut rec, [&x, &w, &out], None, &params, tile).unwrap_err().to_string()
}

#[test]
fn conv2d_cm2_matches_the_reference_on_every_tile_the_device_runs() {
    let ctx = ctx();
    let conv = |t: &Matrix2Tile| t.probe == Matrix2Probe::Conv;
    let tiles: Vec<Matrix2Tile> = ctx.info().matrix2_tiles().into_iter().filter(conv).collect();
    let lavapipe_26 = ctx.info().lavapipe_mesa.is_some_and(|v| v >= (26, 1));
    assert!(
        !(tiles.is_empty() && expect_cooperative() && lavapipe_26),
        "VKDIFF_EXPECT_COOPERATIVE=1 on Mesa 26.1's lavapipe, whose flexible dimensions run the probe: {tiles:?}"
    );
    let same = Padding::same;
    if tiles.is_empty() {
        let tile = built_matrix2_tiles(Matrix2Probe::Conv)[0];
        let c = case(1, [1, tile.m as usize], [tile.k as usize, tile.n as usize], [1, 1], 1, same(0));
        let err = refusal(&ctx, &tile, &c, Dtype::F16);
        assert!(err.contains("does not run the VK_NV_cooperative_matrix2 tile"), "{err}");
        return;
    }
    // A context whose binding limit no tensor below fits.
    let limited = private_ctx();
    limited.choose(|c| c.binding_limit = 256);
    for tile in tiles {
        let (m, n, k) = (tile.m as usize, tile.n as usize, tile.k as usize);
        let vae = Padding { top: 0, left: 0, bottom: 1, right: 1 };
        let cases = [
            // 3×3 over two images whose rows the tile's pixels cross: 3·m pixels.
            case(2, [3, m / 2], [k, 2 * n], [3, 3], 1, same(1)),
            // Stride 2, K-steps of half a tap's channels.
            case(1, [8, m / 2], [2 * k, n], [3, 3], 2, same(1)),
            // diffusers' VAE downsampler: padding on the bottom and right only.
            case(1, [4, m], [k, n], [3, 3], 2, vae),
            case(1, [2, m / 2], [3 * k, n], [1, 1], 1, same(0)),
            // 8 channels: a K-step spans taps, each unit within one.
            case(1, [3, m / 2 + 1], [8, n], [2, 2], 1, same(0)),
            // A fused residual, and ReLU.
            Case { accumulate: true, ..case(2, [3, m / 2], [k, n], [3, 3], 1, same(1)) },
            Case { relu: true, ..case(1, [2, m / 2], [k, 2 * n], [1, 1], 1, same(0)) },
        ];
        for (i, c) in cases.iter().enumerate() {
            check(&ctx, &tile, c, 40 + 3 * i as u64);
        }
        // Channels off the 8-value units, and pixels off the tile, are refused before anything
        // is recorded.
        for c in [case(1, [1, 2 * m], [12, n], [1, 1], 1, same(0)), case(1, [1, m + 1], [k, n], [1, 1], 1, same(0))] {
            let err = refusal(&ctx, &tile, &c, Dtype::F16);
            assert!(err.contains("not a multiple of the tile"), "{err}");
        }
        let err = refusal(&ctx, &tile, &case(1, [1, m], [k, n], [1, 1], 1, same(0)), Dtype::F32);
        assert!(err.contains("must be f16"), "{err}");
        // So is a tensor past the binding limit (`ops::conv2d` bands such convolutions first).
        let err = refusal(&limited, &tile, &case(1, [1, m], [k, n], [1, 1], 1, same(0)), Dtype::F16);
        assert!(err.contains("past the binding limit"), "{err}");
    }
}

#[test]
fn conv2d_takes_the_probe_where_the_context_asks_and_the_tile_fits() {
    // A context of its own: the setting would reach other tests' convolutions in a shared one.
    // Direct where the probe is not taken, so the bound is the direct kernels' (Winograd's
    // F(2×2, 3×3) rounds its transformed tiles too).
    let ctx = private_ctx();
    ctx.choose(|c| c.winograd_from = None);
    let offered = ctx.info().matrix2_tiles().into_iter().find(|t| t.probe == Matrix2Probe::Conv);
    let (m, n, k) = offered.map_or((16, 16, 16), |t| (t.m as usize, t.n as usize, t.k as usize));
    // The first fits the tile; the second's 12 input channels do not.
    let fitting = Case { accumulate: true, ..case(2, [2, m / 2], [k, n], [3, 3], 1, Padding::same(1)) };
    let off = case(1, [2, m / 2], [12, n], [3, 3], 1, Padding::same(1));
    for (c, fits) in [(fitting, true), (off, false)] {
        let ([kh, kw], [ho, wo]) = (c.k, c.out_size());
        let x = stored(&random(c.b * c.h * c.w * c.cin, 51), Dtype::F16);
        let w_oihw = stored(&random(c.cout * c.cin * kh * kw, 52), Dtype::F16);
        let bias = stored(&random(c.cout, 53), Dtype::F16);
        let prior = stored(&random(c.b * ho * wo * c.cout, 54), Dtype::F16);
        let tx = ctx.upload(&[c.b, c.h, c.w, c.cin], Dtype::F16, &x).unwrap();
        let tw =
            ctx.upload(&[c.cout, kh, kw, c.cin], Dtype::F16, &oihw_to_ohwi(&w_oihw, c.cout, c.cin, kh, kw)).unwrap();
        let tb = ctx.upload(&[c.cout], Dtype::F16, &bias).unwrap();
        let prior = if c.accumulate { prior } else { vec![0.0; prior.len()] };
        let (want, mag) = reference(&c, &x, &w_oihw, &bias, &prior);
        let params = ConvParams { stride: c.stride, pad: c.pad, accumulate: c.accumulate, relu: c.relu };
        for kernel in [ProbeChoice::Matrix2, ProbeChoice::Auto] {
            ctx.choose(|c| c.conv = kernel);
            let out = ctx.upload(&[c.b, ho, wo, c.cout], Dtype::F16, &prior).unwrap();
            let ran = ctx.run_listing(|rec| conv2d(rec, &tx, &tw, Some(&tb), &out, &params)).unwrap();
            let ran: Vec<&str> = ran.iter().map(|v| v.kernel).collect();
            let probe = ran.contains(&"conv_cm2");
            let what = format!("conv2d with {kernel:?}, {} input channels", c.cin);
            assert_eq!(probe, offered.is_some() && fits && kernel == ProbeChoice::Matrix2, "{what}: {ran:?}");
            let rtol = storage_rtol(Dtype::F16);
            assert_within(&what, &out.download().unwrap(), &want, |i| 1e-6 + 1e-5 * mag[i] + rtol * want[i].abs());
        }
    }
}
