//! Element-wise kernels, data movement and the timestep embedding against f64 references.

use vkdiff_runtime::ops::{self, BinaryOp, TimestepEmbedding, UnaryOp};
use vkdiff_runtime::{Dtype, Recorder, Result, Tensor};
use vkdiff_testkit::*;

/// The f64 function an activation kernel computes.
type Reference = fn(f64) -> f64;
/// The operand element (batch, position, channel, channels) an output element reads.
type BroadcastIndex = fn(usize, usize, usize, usize) -> usize;

fn erf(x: f64) -> f64 {
    libm::erf(x)
}

/// Runs a one-input op on `x` and compares with `f` applied element-wise.
fn check_unary(
    name: &str,
    x: &[f32],
    out_len: usize,
    run: impl Fn(&mut Recorder, &Tensor, &Tensor) -> Result<()>,
    want: impl Fn(&[f32]) -> Vec<f64>,
) {
    let ctx = ctx();
    for dtype in DTYPES {
        let xs = stored(x, dtype);
        let tx = ctx.upload(&[xs.len()], dtype, &xs).unwrap();
        let out = ctx.zeros(&[out_len], dtype).unwrap();
        ctx.run(|rec| run(rec, &tx, &out)).unwrap();
        // Activations are evaluated in f32: 2e-6 absolute/relative, plus storage rounding.
        assert_close(
            &format!("{name} {dtype:?}"),
            &out.download().unwrap(),
            &want(&xs),
            2e-6,
            2e-6 + storage_rtol(dtype),
        );
    }
}

fn inputs() -> Vec<f32> {
    // Values across the activations' interesting ranges, including exactly 0 and |x| > 10.
    let mut x: Vec<f32> = random(5000, 61).iter().map(|v| 6.0 * v).collect();
    x.extend([0.0, -0.0, 1e-4, -1e-4, 0.5, -0.5, 12.0, -12.0, 30.0, -30.0]);
    x
}

#[test]
fn unary_activations() {
    let x = inputs();
    let cases: [(UnaryOp, Reference); 5] = [
        (UnaryOp::Scale, |v| -1.75 * v),
        (UnaryOp::Silu, |v| v / (1.0 + (-v).exp())),
        (UnaryOp::Gelu, |v| 0.5 * v * (1.0 + erf(v / 2f64.sqrt()))),
        (UnaryOp::GeluTanh, |v| {
            0.5 * v * (1.0 + ((2.0 / std::f64::consts::PI).sqrt() * (v + 0.044715 * v.powi(3))).tanh())
        }),
        (UnaryOp::QuickGelu, |v| v / (1.0 + (-1.702 * v).exp())),
    ];
    // 5010 values take the one-value kernel, 5008 the vec4 one.
    for ((op, f), len) in cases.into_iter().flat_map(|case| [(case, x.len()), (case, x.len() - 2)]) {
        check_unary(
            &format!("{op:?} of {len}"),
            &x[x.len() - len..],
            len,
            |rec, a, o| ops::unary(rec, op, a, o, -1.75),
            |xs| xs.iter().map(|&v| f(v as f64)).collect(),
        );
    }
}

#[test]
fn unary_in_place() {
    let ctx = ctx();
    let x = random(1000, 62);
    let t = ctx.upload(&[1000], Dtype::F32, &x).unwrap();
    ctx.run(|rec| ops::unary(rec, UnaryOp::Silu, &t, &t, 0.0)).unwrap();
    let want: Vec<f64> = x.iter().map(|&v| v as f64 / (1.0 + (-v as f64).exp())).collect();
    assert_close("silu in place", &t.download().unwrap(), &want, 2e-6, 2e-6);
}

#[test]
fn geglu_value_first_gate_second() {
    // F = 40 takes the vec4 kernel, F = 10 the one-value one.
    for (rows, f) in [(7, 40), (5, 10)] {
        geglu_case(rows, f);
    }
}

fn geglu_case(rows: usize, f: usize) {
    let x: Vec<f32> = random(rows * 2 * f, 63).iter().map(|v| 4.0 * v).collect();
    let want = |xs: &[f32]| {
        (0..rows * f)
            .map(|i| {
                let (r, j) = (i / f, i % f);
                let (value, gate) = (xs[r * 2 * f + j] as f64, xs[r * 2 * f + f + j] as f64);
                value * 0.5 * gate * (1.0 + erf(gate / 2f64.sqrt()))
            })
            .collect()
    };
    check_unary(
        "geglu",
        &x,
        rows * f,
        |rec, a, o| ops::geglu(rec, &a.reshape(&[rows, 2 * f])?, &o.reshape(&[rows, f])?),
        want,
    );
}

#[test]
fn add_and_mul_with_broadcasting() {
    let ctx = ctx();
    // 12 channels take the vec4 kernel, 13 the one-value one.
    for (dtype, c) in DTYPES.into_iter().flat_map(|d| [(d, 12), (d, 13)]) {
        let (b, hw) = (2, 15);
        let a = stored(&random(b * hw * c, 64), dtype);
        let ta = ctx.upload(&[b, hw, c], dtype, &a).unwrap();
        // Same shape, per channel, per (batch, channel).
        let cases: [(Vec<usize>, BroadcastIndex); 3] = [
            (vec![b, hw, c], |n, s, ch, c| (n * 15 + s) * c + ch),
            (vec![c], |_, _, ch, _| ch),
            (vec![b, 1, c], |n, _, ch, c| n * c + ch),
        ];
        for (shape, index) in cases {
            let bv = stored(&random(shape.iter().product(), 65), dtype);
            let tb = ctx.upload(&shape, dtype, &bv).unwrap();
            for op in [BinaryOp::Add, BinaryOp::Mul] {
                let out = ctx.zeros(&[b, hw, c], dtype).unwrap();
                ctx.run(|rec| match op {
                    BinaryOp::Add => ops::add(rec, &ta, &tb, &out),
                    BinaryOp::Mul => ops::mul(rec, &ta, &tb, &out),
                })
                .unwrap();
                let mut want = vec![0.0; a.len()];
                for n in 0..b {
                    for s in 0..hw {
                        for ch in 0..c {
                            let (x, y) = (a[(n * hw + s) * c + ch] as f64, bv[index(n, s, ch, c)] as f64);
                            want[(n * hw + s) * c + ch] = if op == BinaryOp::Add { x + y } else { x * y };
                        }
                    }
                }
                assert_close(
                    &format!("{op:?} {dtype:?} by {shape:?}"),
                    &out.download().unwrap(),
                    &want,
                    1e-7,
                    storage_rtol(dtype),
                );
            }
        }
    }
}

#[test]
fn upsample_nearest_2x() {
    // 6 channels take the one-value kernel, 8 the vec4 one.
    for c in [6, 8] {
        upsample_case(c);
    }
}

fn upsample_case(c: usize) {
    let (b, h, w) = (2, 3, 5);
    let x = random(b * h * w * c, 66);
    let want = |xs: &[f32]| {
        let mut out = Vec::new();
        for n in 0..b {
            for y in 0..2 * h {
                for xx in 0..2 * w {
                    for ch in 0..c {
                        out.push(xs[((n * h + y / 2) * w + xx / 2) * c + ch] as f64);
                    }
                }
            }
        }
        out
    };
    check_unary(
        "upsample",
        &x,
        4 * x.len(),
        |rec, a, o| ops::upsample_nearest2x(rec, &a.reshape(&[b, h, w, c])?, &o.reshape(&[b, 2 * h, 2 * w, c])?),
        want,
    );
}

#[test]
fn concat_along_channels() {
    let ctx = ctx();
    // 5 + 7 channels take the one-value kernel, 8 + 12 the vec4 one.
    for (dtype, (c1, c2)) in DTYPES.into_iter().flat_map(|d| [(d, (5, 7)), (d, (8, 12))]) {
        let pix = 2 * 9;
        let a = stored(&random(pix * c1, 67), dtype);
        let bv = stored(&random(pix * c2, 68), dtype);
        let ta = ctx.upload(&[2, 9, c1], dtype, &a).unwrap();
        let tb = ctx.upload(&[2, 9, c2], dtype, &bv).unwrap();
        let out = ctx.zeros(&[2, 9, c1 + c2], dtype).unwrap();
        ctx.run(|rec| ops::concat_channels(rec, &ta, &tb, &out)).unwrap();
        let want: Vec<f64> = (0..pix)
            .flat_map(|p| {
                a[p * c1..(p + 1) * c1].iter().chain(&bv[p * c2..(p + 1) * c2]).map(|&v| v as f64).collect::<Vec<_>>()
            })
            .collect();
        assert_close(&format!("concat {c1}+{c2} {dtype:?}"), &out.download().unwrap(), &want, 0.0, 1e-9);
    }
}

#[test]
fn timestep_embedding_like_diffusers() {
    let ctx = ctx();
    let t = [999.0f32, 500.5, 1.0, 0.0, 761.0];
    let tt = ctx.upload(&[t.len()], Dtype::F32, &t).unwrap();
    for dtype in DTYPES {
        for (dim, flip, shift) in [(320usize, true, 0.0f32), (256, false, 1.0), (33, true, 0.0)] {
            let e = TimestepEmbedding {
                dim,
                flip_sin_to_cos: flip,
                downscale_freq_shift: shift,
                max_period: 10000.0,
                scale: 1.0,
            };
            let out = ctx.zeros(&[t.len(), dim], dtype).unwrap();
            ctx.run(|rec| ops::timestep_embedding(rec, &tt, &out, &e)).unwrap();
            let half = dim / 2;
            let mut want = vec![0.0f64; t.len() * dim];
            for (b, &tv) in t.iter().enumerate() {
                for k in 0..half {
                    // The argument as PyTorch forms it in f32, then sin/cos exactly.
                    let freq = (-(10000f32.ln()) * k as f32 / (half as f32 - shift)).exp();
                    let a = (tv * freq) as f64;
                    let (first, second) = if flip { (a.cos(), a.sin()) } else { (a.sin(), a.cos()) };
                    want[b * dim + k] = first;
                    want[b * dim + half + k] = second;
                }
            }
            // f32 exp() and the argument differ from PyTorch's by an ulp of |a| ≤ 1000: 2e-4.
            assert_close(
                &format!("timestep dim {dim} flip {flip} {dtype:?}"),
                &out.download().unwrap(),
                &want,
                2e-4,
                storage_rtol(dtype),
            );
        }
    }
}
