//! Inception's spatial kernels against f64 references: max and average pooling (padding, stride,
//! global), the TensorFlow 1.x bilinear resize, and writing a branch into a channel slice.

use vkdiff_runtime::ops::{copy_into_channels, pool2d, resize_tf1, upload_image_bytes, Pool, PoolOp};
use vkdiff_testkit::*;

/// Reference pooling of NHWC `x` [b, h, w, c].
fn pool_ref(x: &[f32], [b, h, w, c]: [usize; 4], p: &Pool) -> Vec<f64> {
    let [ho, wo] = p.output_size(h, w).unwrap();
    let mut out = Vec::with_capacity(b * ho * wo * c);
    for n in 0..b {
        for oy in 0..ho {
            for ox in 0..wo {
                for ch in 0..c {
                    let taps: Vec<f64> = (0..p.window[0])
                        .flat_map(|ky| (0..p.window[1]).map(move |kx| (ky, kx)))
                        .filter_map(|(ky, kx)| {
                            let y = (oy * p.stride + ky).checked_sub(p.pad).filter(|&y| y < h)?;
                            let x_ = (ox * p.stride + kx).checked_sub(p.pad).filter(|&x_| x_ < w)?;
                            Some(x[((n * h + y) * w + x_) * c + ch] as f64)
                        })
                        .collect();
                    out.push(match p.op {
                        PoolOp::Max => taps.iter().copied().fold(f64::NEG_INFINITY, f64::max),
                        PoolOp::Average => taps.iter().sum::<f64>() / taps.len() as f64,
                    });
                }
            }
        }
    }
    out
}

fn check_pool(shape: [usize; 4], pool: Pool, seed: u64) {
    let ctx = ctx();
    let [b, h, w, c] = shape;
    let [ho, wo] = pool.output_size(h, w).unwrap();
    for dtype in DTYPES {
        // Negative inputs everywhere near a padded edge would expose a zero-padded max.
        let x: Vec<f32> = stored(&random(b * h * w * c, seed).iter().map(|v| v - 0.5).collect::<Vec<_>>(), dtype);
        let tx = ctx.upload(&shape, dtype, &x).unwrap();
        let out = ctx.zeros(&[b, ho, wo, c], dtype).unwrap();
        ctx.run(|rec| pool2d(rec, &tx, &out, &pool)).unwrap();
        assert_close(
            &format!("{pool:?} {shape:?} {dtype:?}"),
            &out.download().unwrap(),
            &pool_ref(&x, shape, &pool),
            1e-6,
            1e-6 + storage_rtol(dtype),
        );
    }
}

#[test]
fn max_pool_stride2_and_padded() {
    check_pool([2, 9, 11, 8], Pool { op: PoolOp::Max, window: [3, 3], stride: 2, pad: 0 }, 71);
    // InceptionE_2's branch pool: 3×3, stride 1, padding 1.
    check_pool([1, 6, 5, 12], Pool { op: PoolOp::Max, window: [3, 3], stride: 1, pad: 1 }, 72);
}

#[test]
fn average_pool_counts_only_taps_inside() {
    check_pool([2, 7, 6, 20], Pool { op: PoolOp::Average, window: [3, 3], stride: 1, pad: 1 }, 73);
}

#[test]
fn global_average_pool() {
    check_pool([3, 8, 8, 36], Pool::global_average(8, 8), 74);
    check_pool([1, 5, 3, 4], Pool::global_average(5, 3), 75);
}

#[test]
fn pools_one_image_at_a_time_past_the_binding_limit() {
    let ctx = ctx_with(vkdiff_runtime::GemmFamily::Subgroup);
    let (shape, pool) = ([3, 16, 16, 16], Pool { op: PoolOp::Max, window: [3, 3], stride: 1, pad: 1 });
    let x = random(shape.iter().product(), 76);
    let tx = ctx.upload(&shape, vkdiff_runtime::Dtype::F32, &x).unwrap();
    let out = ctx.zeros(&shape, vkdiff_runtime::Dtype::F32).unwrap();
    ctx.choose(|c| c.binding_limit = 16 * 16 * 16 * 4);
    ctx.run(|rec| pool2d(rec, &tx, &out, &pool)).unwrap();
    assert_close("banded max pool", &out.download().unwrap(), &pool_ref(&x, shape, &pool), 0.0, 0.0);
}

/// torch-fidelity's `interpolate_bilinear_2d_like_tensorflow1x` of an 8-bit image, then
/// (v − 128)/128, in the same float32 steps.
fn resize_ref(x: &[u8], [h, w, c]: [usize; 3], ho: usize, wo: usize) -> Vec<f64> {
    let axis = |n_in: usize, n_out: usize| {
        let scale = (n_in as f64 / n_out as f64) as f32;
        (0..n_out).map(move |d| {
            let g = d as f32 * scale;
            let lo = g as usize;
            (lo, (lo + 1).min(n_in - 1), g - lo as f32)
        })
    };
    let mut out = Vec::new();
    for (y0, y1, dy) in axis(h, ho) {
        for (x0, x1, dx) in axis(w, wo) {
            for ch in 0..c {
                let at = |y: usize, x_: usize| x[(y * w + x_) * c + ch] as f32;
                let top = at(y0, x0) + (at(y0, x1) - at(y0, x0)) * dx;
                let bottom = at(y1, x0) + (at(y1, x1) - at(y1, x0)) * dx;
                out.push(((top + (bottom - top) * dy - 128.0) / 128.0) as f64);
            }
        }
    }
    out
}

fn bytes(n: usize, seed: u64) -> Vec<u8> {
    random(n, seed).iter().map(|v| ((v + 1.0) * 127.9) as u8).collect()
}

#[test]
fn resize_like_tensorflow1x() {
    let ctx = ctx();
    // Down- and up-sampling, non-square, to Inception's 299; 5·7·3 bytes end inside a word.
    for ([h, w], ho, wo) in [([37, 23], 19, 41), ([320, 256], 299, 299), ([64, 48], 299, 299), ([5, 7], 3, 4)] {
        for dtype in DTYPES {
            let pixels = bytes(h * w * 3, 77);
            let image = upload_image_bytes(&ctx, &pixels).unwrap();
            let out = ctx.zeros(&[1, ho, wo, 3], dtype).unwrap();
            ctx.run(|rec| resize_tf1(rec, &image, [h, w, 3], &out, 0, -128.0, 1.0 / 128.0)).unwrap();
            // The interpolation runs in f32 as in torch-fidelity.
            let what = format!("resize {h}x{w} -> {ho}x{wo} {dtype:?}");
            assert_close(
                &what,
                &out.download().unwrap(),
                &resize_ref(&pixels, [h, w, 3], ho, wo),
                2e-6,
                storage_rtol(dtype),
            );
        }
    }
}

#[test]
fn resize_into_a_later_slot_of_the_batch_padded_to_four_channels() {
    let ctx = ctx();
    let pixels = bytes(9 * 14 * 3, 78);
    let image = upload_image_bytes(&ctx, &pixels).unwrap();
    // A fourth channel, which the resize fills with zeros.
    let out = ctx.upload(&[3, 5, 6, 4], vkdiff_runtime::Dtype::F32, &[7.0; 3 * 5 * 6 * 4]).unwrap();
    ctx.run(|rec| resize_tf1(rec, &image, [9, 14, 3], &out, 2, -128.0, 1.0 / 128.0)).unwrap();
    let mut want = vec![7.0; 2 * 5 * 6 * 4];
    want.extend(resize_ref(&pixels, [9, 14, 3], 5, 6).chunks(3).flat_map(|px| [px[0], px[1], px[2], 0.0]));
    assert_close("resize into slot 2, padded to 4 channels", &out.download().unwrap(), &want, 2e-6, 1e-6);
}

/// Three branches of [2, 5, 3, C] written side by side into one tensor on `ctx`.
fn check_channel_slices(ctx: &vkdiff_runtime::Context, what: &str) {
    for dtype in DTYPES {
        let (pixels, widths) = (2 * 5 * 3, [4, 12, 8]);
        let total: usize = widths.iter().sum();
        let out = ctx.zeros(&[2, 5, 3, total], dtype).unwrap();
        let mut want = vec![0.0f64; pixels * total];
        let mut offset = 0;
        for (k, &c) in widths.iter().enumerate() {
            let x = stored(&random(pixels * c, 80 + k as u64), dtype);
            let tx = ctx.upload(&[2, 5, 3, c], dtype, &x).unwrap();
            ctx.run(|rec| copy_into_channels(rec, &tx, &out, offset)).unwrap();
            for p in 0..pixels {
                for ch in 0..c {
                    want[p * total + offset + ch] = x[p * c + ch] as f64;
                }
            }
            offset += c;
        }
        assert_close(&format!("{what} {dtype:?}"), &out.download().unwrap(), &want, 0.0, 0.0);
    }
}

#[test]
fn branches_written_into_channel_slices() {
    check_channel_slices(&ctx(), "channel slices");
}

#[test]
fn channel_slices_in_bands_past_the_binding_limit() {
    let ctx = ctx_with(vkdiff_runtime::GemmFamily::Subgroup);
    // 8 pixels of the 24-channel output per binding in f16, 4 in f32: the 30 pixels go in bands.
    ctx.choose(|c| c.binding_limit = 8 * 24 * 2);
    check_channel_slices(&ctx, "banded channel slices");
}
