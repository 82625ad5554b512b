//! Ops on tensors past the binding limit run in bands of rows. A private context with a tiny
//! limit forces the bands; they must give what the whole-tensor dispatch gives.

use crate::common::*;
use vkdiff_runtime::ops::{conv2d, geglu, group_norm, matmul, upsample_nearest2x, ConvParams, Matmul, Padding};
use vkdiff_runtime::{Context, Dtype, Recorder, Tensor};

const LIMIT: u64 = 4096;

/// Runs `op` once with the device's own limit and once with `LIMIT`, returning both outputs.
fn whole_and_banded(dtype: Dtype, shapes: &[&[usize]], out: &[usize], op: impl Fn(&mut Recorder, &[Tensor], &Tensor) -> vkdiff_runtime::Result<()>) -> (Vec<f32>, Vec<f32>) {
    let ctx = ctx_with(ctx().gemm_family());
    let inputs: Vec<Tensor> = shapes
        .iter()
        .enumerate()
        .map(|(i, s)| ctx.upload(s, dtype, &random(s.iter().product(), 40 + i as u64)).unwrap())
        .collect();
    let run = |ctx: &Context| {
        let o = ctx.upload(out, dtype, &random(out.iter().product(), 7)).unwrap();
        ctx.run(|rec| op(rec, &inputs, &o)).unwrap();
        o.download().unwrap()
    };
    let whole = run(&ctx);
    ctx.set_binding_limit(LIMIT);
    let out_bytes = out.iter().product::<usize>() as u64 * inputs[0].bytes() / inputs[0].numel() as u64;
    assert!(out_bytes > LIMIT || inputs.iter().any(|t| t.bytes() > LIMIT), "the test must pass the limit");
    (whole, run(&ctx))
}

fn assert_same(what: &str, whole: &[f32], banded: &[f32]) {
    let want: Vec<f64> = whole.iter().map(|&v| v as f64).collect();
    assert_close(what, banded, &want, 0.0, 0.0);
}

#[test]
fn conv_bands_match_the_whole_convolution() {
    let square = ConvParams::new(1, 1);
    let down = ConvParams { stride: 2, pad: Padding { top: 0, left: 0, bottom: 1, right: 1 }, accumulate: true };
    let shortcut = ConvParams { accumulate: true, ..ConvParams::new(1, 0) };
    for dtype in DTYPES {
        for (name, p, k, out) in [("3x3", square, 3, [2, 21, 16, 8]), ("stride 2, pad bottom-right", down, 3, [2, 10, 8, 8]), ("1x1", shortcut, 1, [2, 21, 16, 8])] {
            let shapes: [&[usize]; 3] = [&[2, 21, 16, 8], &[8, k, k, 8], &[8]];
            let (whole, banded) = whole_and_banded(dtype, &shapes, &out, |rec, t, o| conv2d(rec, &t[0], &t[1], Some(&t[2]), o, &p));
            assert_same(&format!("conv {name} {dtype:?}"), &whole, &banded);
        }
    }
}

#[test]
fn group_norm_bands_merge_statistics_exactly_enough() {
    for dtype in DTYPES {
        let shapes: [&[usize]; 3] = [&[2, 13, 8, 16], &[16], &[16]];
        let (whole, banded) = whole_and_banded(dtype, &shapes, &[2, 13, 8, 16], |rec, t, o| group_norm(rec, &t[0], &t[1], &t[2], o, 4, 1e-6, true));
        let want: Vec<f64> = whole.iter().map(|&v| v as f64).collect();
        // Chan's merge of band statistics rounds differently from one two-pass sum.
        assert_close(&format!("group_norm {dtype:?}"), &banded, &want, 1e-5, storage_rtol(dtype));
    }
}

#[test]
fn upsample_linear_and_geglu_bands_match() {
    for dtype in DTYPES {
        let (whole, banded) = whole_and_banded(dtype, &[&[2, 9, 4, 8]], &[2, 18, 8, 8], |rec, t, o| upsample_nearest2x(rec, &t[0], o));
        assert_same(&format!("upsample {dtype:?}"), &whole, &banded);
        let mut spec = Matmul::dense(300, 24, 16, true);
        (spec.alpha, spec.accumulate) = (0.5, true);
        let shapes: [&[usize]; 3] = [&[300, 16], &[24, 16], &[24]];
        let (whole, banded) = whole_and_banded(dtype, &shapes, &[300, 24], |rec, t, o| matmul(rec, &t[0], &t[1], Some(&t[2]), o, &spec));
        assert_same(&format!("matmul {dtype:?}"), &whole, &banded);
        let (whole, banded) = whole_and_banded(dtype, &[&[100, 64]], &[100, 32], |rec, t, o| geglu(rec, &t[0], o));
        assert_same(&format!("geglu {dtype:?}"), &whole, &banded);
    }
}
