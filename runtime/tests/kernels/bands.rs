//! Ops on tensors past the binding limit run in bands of rows. A private context with a tiny
//! limit forces the bands; they must give what the whole-tensor dispatch gives.

use vkdiff_runtime::ops::{
    add, attention, concat_channels, conv2d, geglu, group_norm, layer_norm, matmul, mul, softmax, unary,
    upsample_nearest2x, AttentionLayout, ConvParams, Matmul, Padding, UnaryOp,
};
use vkdiff_runtime::{Context, Dtype, Recorder, Tensor};
use vkdiff_testkit::*;

const LIMIT: u64 = 4096;

type Op<'a> = &'a dyn Fn(&mut Recorder, &[Tensor], &Tensor) -> vkdiff_runtime::Result<()>;

/// Runs `op` once with the device's own limit and once with `LIMIT`, returning both outputs.
fn whole_and_banded(
    dtype: Dtype,
    shapes: &[&[usize]],
    out: &[usize],
    op: impl Fn(&mut Recorder, &[Tensor], &Tensor) -> vkdiff_runtime::Result<()>,
) -> (Vec<f32>, Vec<f32>) {
    whole_and_limited(dtype, shapes, out, &op, |ctx| ctx.choose(|c| c.binding_limit = LIMIT))
}

/// Runs `op` once on a fresh context and once after `limit` lowered one of its limits.
fn whole_and_limited(
    dtype: Dtype,
    shapes: &[&[usize]],
    out: &[usize],
    op: Op,
    limit: impl Fn(&Context),
) -> (Vec<f32>, Vec<f32>) {
    let ctx = ctx_with(ctx().choices().gemm_family);
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
    limit(&ctx);
    let out_bytes = out.iter().product::<usize>() as u64 * inputs[0].bytes() / inputs[0].numel() as u64;
    let passed =
        out_bytes > ctx.choices().binding_limit || inputs.iter().any(|t| t.bytes() > ctx.choices().binding_limit);
    assert!(passed || ctx.choices().workgroup_limit != ctx.info().max_workgroup_count, "the test must pass a limit");
    (whole, run(&ctx))
}

fn assert_same(what: &str, whole: &[f32], banded: &[f32]) {
    let want: Vec<f64> = whole.iter().map(|&v| v as f64).collect();
    assert_close(what, banded, &want, 0.0, 0.0);
}

#[test]
fn conv_bands_match_the_whole_convolution() {
    let square = ConvParams::new(1, 1);
    let down =
        ConvParams { stride: 2, pad: Padding { top: 0, left: 0, bottom: 1, right: 1 }, accumulate: true, relu: false };
    let shortcut = ConvParams { accumulate: true, ..ConvParams::new(1, 0) };
    for dtype in DTYPES {
        for (name, p, k, cin, out) in [
            ("3x3", square, 3, 8, [2, 21, 16, 8]),
            ("stride 2, pad bottom-right", down, 3, 8, [2, 10, 8, 8]),
            ("1x1", shortcut, 1, 8, [2, 21, 16, 8]),
            ("3 into 5 channels, padded to 4 and 8", shortcut, 3, 3, [2, 19, 14, 5]),
        ] {
            let cout = out[3];
            let shapes: [&[usize]; 3] = [&[2, 21, 16, cin], &[cout, k, k, cin], &[cout]];
            let (whole, banded) =
                whole_and_banded(dtype, &shapes, &out, |rec, t, o| conv2d(rec, &t[0], &t[1], Some(&t[2]), o, &p));
            assert_same(&format!("conv {name} {dtype:?}"), &whole, &banded);
        }
    }
}

#[test]
fn group_norm_bands_merge_statistics_exactly_enough() {
    // Groups of 4, 2 and 3 channels: four, two and one a step.
    for (dtype, c) in DTYPES.into_iter().flat_map(|d| [(d, 16), (d, 8), (d, 12)]) {
        let x = [2, 13, 16, c];
        let shapes: [&[usize]; 3] = [&x, &[c], &[c]];
        let (whole, banded) =
            whole_and_banded(dtype, &shapes, &x, |rec, t, o| group_norm(rec, &t[0], &t[1], &t[2], o, 4, 1e-6, true));
        let want: Vec<f64> = whole.iter().map(|&v| v as f64).collect();
        // Chan's merge of band statistics rounds differently from one two-pass sum.
        assert_close(&format!("group_norm {c} channels {dtype:?}"), &banded, &want, 1e-5, storage_rtol(dtype));
    }
}

#[test]
fn upsample_linear_and_geglu_bands_match() {
    for dtype in DTYPES {
        let (whole, banded) =
            whole_and_banded(dtype, &[&[2, 9, 4, 8]], &[2, 18, 8, 8], |rec, t, o| upsample_nearest2x(rec, &t[0], o));
        assert_same(&format!("upsample {dtype:?}"), &whole, &banded);
        let mut spec = Matmul::dense(300, 24, 16, true);
        (spec.alpha, spec.accumulate) = (0.5, true);
        let shapes: [&[usize]; 3] = [&[300, 16], &[24, 16], &[24]];
        let (whole, banded) =
            whole_and_banded(dtype, &shapes, &[300, 24], |rec, t, o| matmul(rec, &t[0], &t[1], Some(&t[2]), o, &spec));
        assert_same(&format!("matmul {dtype:?}"), &whole, &banded);
        let mut batched = Matmul::dense(64, 24, 16, false);
        (batched.batch, batched.b_batch) = (3, 16 * 24);
        let shapes: [&[usize]; 2] = [&[3, 64, 16], &[3, 16, 24]];
        let (whole, banded) =
            whole_and_banded(dtype, &shapes, &[3, 64, 24], |rec, t, o| matmul(rec, &t[0], &t[1], None, o, &batched));
        assert_same(&format!("batched matmul {dtype:?}"), &whole, &banded);
        let (whole, banded) = whole_and_banded(dtype, &[&[100, 64]], &[100, 32], |rec, t, o| geglu(rec, &t[0], o));
        assert_same(&format!("geglu {dtype:?}"), &whole, &banded);
    }
}

#[test]
fn broadcast_add_and_mul_bands_bind_what_they_read() {
    // Same shape, a per-channel vector, and a per-(batch, channel) vector over pixels; 16
    // channels take the vec4 kernel, 15 the one-value one.
    for (dtype, c) in DTYPES.into_iter().flat_map(|d| [(d, 16), (d, 15)]) {
        let a = [2, 13, 8, c];
        for b in [&a[..], &[c], &[2, 1, 1, c]] {
            let (whole, banded) = whole_and_banded(dtype, &[&a, b], &a, |rec, t, o| add(rec, &t[0], &t[1], o));
            assert_same(&format!("add {b:?} {dtype:?}"), &whole, &banded);
            let (whole, banded) = whole_and_banded(dtype, &[&a, b], &a, |rec, t, o| mul(rec, &t[0], &t[1], o));
            assert_same(&format!("mul {b:?} {dtype:?}"), &whole, &banded);
        }
        let silu = |rec: &mut Recorder, t: &[Tensor], o: &Tensor| unary(rec, UnaryOp::Silu, &t[0], o, 1.0);
        let n = 201 * c;
        let (whole, banded) = whole_and_banded(dtype, &[&[n]], &[n], silu);
        assert_same(&format!("silu of {n} {dtype:?}"), &whole, &banded);
    }
}

#[test]
fn concat_layer_norm_and_softmax_bands_match() {
    for dtype in DTYPES {
        // 12 + 4 channels take the vec4 kernel, 5 + 7 the one-value one.
        for (c1, c2) in [(12, 4), (5, 7)] {
            let shapes: [&[usize]; 2] = [&[2, 9, 16, c1], &[2, 9, 16, c2]];
            let (whole, banded) = whole_and_banded(dtype, &shapes, &[2, 9, 16, c1 + c2], |rec, t, o| {
                concat_channels(rec, &t[0], &t[1], o)
            });
            assert_same(&format!("concat {c1}+{c2} {dtype:?}"), &whole, &banded);
        }
        let (whole, banded) = whole_and_banded(dtype, &[&[100, 24], &[24], &[24]], &[100, 24], |rec, t, o| {
            layer_norm(rec, &t[0], &t[1], &t[2], o, 1e-5)
        });
        assert_same(&format!("layer_norm {dtype:?}"), &whole, &banded);
        let (whole, banded) =
            whole_and_banded(dtype, &[&[100, 24]], &[100, 24], |rec, t, o| softmax(rec, &t[0], o, 0.7));
        assert_same(&format!("softmax {dtype:?}"), &whole, &banded);
    }
}

/// Self-attention over a fused [B, N, 3·H·D] projection (Q, K, V at column offsets 0, H·D, 2·H·D).
fn fused_attention(
    heads: usize,
    d: usize,
    n: usize,
    causal: bool,
) -> impl Fn(&mut Recorder, &[Tensor], &Tensor) -> vkdiff_runtime::Result<()> {
    move |rec, t, o| {
        let w = heads * d;
        let mut l = AttentionLayout::dense(2, heads, d, n, n);
        (l.q_ld, l.k_ld, l.v_ld) = (3 * w, 3 * w, 3 * w);
        (l.q_batch, l.k_batch, l.v_batch) = (n * 3 * w, n * 3 * w, n * 3 * w);
        (l.k_offset, l.v_offset, l.causal) = (w, 2 * w, causal);
        attention(rec, &t[0], &t[0], &t[0], o, &l, 1.0 / (d as f32).sqrt())
    }
}

#[test]
fn attention_past_the_limit_runs_per_batch_or_per_head_group() {
    // 4 KiB: each head group copied into dense operands. 0: a limit one batch fits, so one
    // batch at a time on views.
    for dtype in DTYPES {
        for (limit, heads, d, n, causal) in [(LIMIT, 3, 16, 40, false), (LIMIT, 2, 5, 41, true), (0, 2, 8, 48, false)] {
            let one_batch = (n * 3 * heads * d * if dtype == Dtype::F32 { 4 } else { 2 }) as u64;
            let limit = if limit == 0 { one_batch + 256 } else { limit };
            let op = fused_attention(heads, d, n, causal);
            let (whole, banded) = whole_and_limited(dtype, &[&[2, n, 3 * heads * d]], &[2, n, heads * d], &op, |ctx| {
                ctx.choose(|c| c.binding_limit = limit)
            });
            assert_same(&format!("attention limit {limit} h{heads} d{d} {dtype:?}"), &whole, &banded);
        }
    }
}

#[test]
fn grids_past_the_workgroup_count_limit_run_as_based_dispatches() {
    let few = |ctx: &Context| ctx.choose(|c| c.workgroup_limit = [3, 2, 1]);
    for dtype in DTYPES {
        let spec = Matmul::dense(300, 200, 16, true);
        let op = |rec: &mut Recorder, t: &[Tensor], o: &Tensor| matmul(rec, &t[0], &t[1], None, o, &spec);
        let (whole, split) = whole_and_limited(dtype, &[&[300, 16], &[200, 16]], &[300, 200], &op, few);
        assert_same(&format!("matmul {dtype:?}"), &whole, &split);
        let op =
            |rec: &mut Recorder, t: &[Tensor], o: &Tensor| conv2d(rec, &t[0], &t[1], None, o, &ConvParams::new(1, 1));
        let (whole, split) = whole_and_limited(dtype, &[&[2, 21, 16, 8], &[8, 3, 3, 8]], &[2, 21, 16, 8], &op, few);
        assert_same(&format!("conv {dtype:?}"), &whole, &split);
        let op = fused_attention(3, 16, 40, false);
        let (whole, split) = whole_and_limited(dtype, &[&[2, 40, 144]], &[2, 40, 48], &op, few);
        assert_same(&format!("attention {dtype:?}"), &whole, &split);
        let op = |rec: &mut Recorder, t: &[Tensor], o: &Tensor| unary(rec, UnaryOp::Silu, &t[0], o, 1.0);
        let (whole, split) = whole_and_limited(dtype, &[&[1000]], &[1000], &op, few);
        assert_same(&format!("silu {dtype:?}"), &whole, &split);
    }
}
