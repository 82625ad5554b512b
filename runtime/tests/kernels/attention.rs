//! Fused attention against an f64 softmax(QKᵀ)V, for self- and cross-attention and many head sizes.

use vkdiff_runtime::ops::{attention, AttentionLayout};
use vkdiff_runtime::{Context, Dtype, GemmFamily, Recorder, Variant};
use vkdiff_testkit::*;

pub(super) fn reference(q: &[f32], k: &[f32], v: &[f32], l: &AttentionLayout, scale: f64) -> Vec<f64> {
    let d = l.head_dim;
    let mut out = vec![0.0f64; l.batch * l.q_tokens * l.heads * d];
    let mut scores = vec![0.0f64; l.kv_tokens];
    for b in 0..l.batch {
        for h in 0..l.heads {
            for i in 0..l.q_tokens {
                let qi = &q[l.q_offset + b * l.q_batch + i * l.q_ld + h * d..][..d];
                for (j, s) in scores.iter_mut().enumerate() {
                    if l.causal && j > i {
                        *s = f64::NEG_INFINITY;
                        continue;
                    }
                    let kj = &k[l.k_offset + b * l.k_batch + j * l.k_ld + h * d..][..d];
                    *s = scale * qi.iter().zip(kj).map(|(&x, &y)| x as f64 * y as f64).sum::<f64>();
                }
                let m = scores.iter().cloned().fold(f64::MIN, f64::max);
                let total: f64 = scores.iter().map(|s| (s - m).exp()).sum();
                for (j, s) in scores.iter().enumerate() {
                    let p = (s - m).exp() / total;
                    let vj = &v[l.v_offset + b * l.v_batch + j * l.v_ld + h * d..][..d];
                    for (e, &vv) in vj.iter().enumerate() {
                        out[((b * l.q_tokens + i) * l.heads + h) * d + e] += p * vv as f64;
                    }
                }
            }
        }
    }
    out
}

/// Runs attention on random Q, K, V laid out as `l` (output dense) and compares, with the
/// device's own kernel choice and on the GPU paths (workgroup attention).
fn check(dtype: Dtype, l: &AttentionLayout, seed: u64) {
    for ctx in [ctx(), gpu_ctx()] {
        check_on(&ctx, dtype, l, seed);
    }
}

fn check_on(ctx: &Context, dtype: Dtype, l: &AttentionLayout, seed: u64) -> Ran {
    check_with_key_gain(ctx, dtype, l, seed, |_| 1.0)
}

/// The kernels an attention dispatched, in order, and the variants it recorded.
type Ran = (Vec<&'static str>, Vec<&'static Variant>);

/// As [`check_on`], with key token t's K values multiplied by `gain(t)`.
fn check_with_key_gain(
    ctx: &Context,
    dtype: Dtype,
    l: &AttentionLayout,
    seed: u64,
    gain: impl Fn(usize) -> f32,
) -> Ran {
    let extent =
        |off: usize, ld: usize, bs: usize, n: usize| off + (l.batch - 1) * bs + (n - 1) * ld + l.heads * l.head_dim;
    let q = stored(&random(extent(l.q_offset, l.q_ld, l.q_batch, l.q_tokens), seed), dtype);
    let mut k = random(extent(l.k_offset, l.k_ld, l.k_batch, l.kv_tokens), seed + 1);
    for (i, x) in k.iter_mut().enumerate().skip(l.k_offset) {
        *x *= gain((i - l.k_offset) % l.k_batch.max(1) / l.k_ld);
    }
    let k = stored(&k, dtype);
    let v = stored(&random(extent(l.v_offset, l.v_ld, l.v_batch, l.kv_tokens), seed + 2), dtype);
    let tq = ctx.upload(&[q.len()], dtype, &q).unwrap();
    let tk = ctx.upload(&[k.len()], dtype, &k).unwrap();
    let tv = ctx.upload(&[v.len()], dtype, &v).unwrap();
    let width = l.heads * l.head_dim;
    let out = ctx.zeros(&[l.batch, l.q_tokens, width], dtype).unwrap();
    let mut dense = l.clone();
    dense.o_ld = width;
    dense.o_batch = l.q_tokens * width;
    // Scores of O(4): the softmax is peaked enough that a wrong max or sum shows.
    let scale = 4.0 / (l.head_dim as f32).sqrt();
    let mut rec = Recorder::new(ctx, true).unwrap();
    attention(&mut rec, &tq, &tk, &tv, &out, &dense, scale).unwrap();
    let recording = rec.finish().unwrap();
    let kernels: Vec<&'static str> = recording.run_profiled().unwrap().iter().map(|t| t.kernel).collect();
    let want = reference(&q, &k, &v, l, scale as f64);
    // Outputs are convex combinations of V (|v| ≤ 1): f32 error stays under 1e-5 absolute.
    let atol = match dtype {
        Dtype::F32 => 1e-5,
        Dtype::F16 => 1e-3,
    };
    let what = format!(
        "attention (GPU paths: {}) {dtype:?} b{} h{} d{} {}x{}",
        ctx.choices().gpu_paths,
        l.batch,
        l.heads,
        l.head_dim,
        l.q_tokens,
        l.kv_tokens
    );
    assert_close(&what, &out.download().unwrap(), &want, atol, storage_rtol(dtype));
    let variants = recording.variants();
    assert_attention_kernel(ctx, dtype, l.head_dim, &variants, &what);
    (kernels, variants)
}

#[test]
fn self_attention_4096_tokens_head_dim_64() {
    for dtype in DTYPES {
        check(dtype, &AttentionLayout::dense(1, 2, 64, 4096, 4096), 41);
    }
}

#[test]
fn cross_attention_77_tokens() {
    for dtype in DTYPES {
        check(dtype, &AttentionLayout::dense(2, 5, 64, 300, 77), 42);
    }
}

#[test]
fn head_sizes() {
    // 8 and 40: tiny models and SD1.x; 24: two slots per lane at 4 lanes; 80: CLIP ViT-H vision;
    // 104: ViT-bigG; 160: the 8-slot variant; 512: the VAE's single-head mid-block attention;
    // 1024: past every subgroup variant. Token counts off every tile size.
    for (d, nq, nk) in
        [(8, 19, 23), (24, 15, 9), (40, 33, 77), (80, 21, 50), (104, 9, 13), (160, 11, 19), (512, 17, 29), (1024, 5, 7)]
    {
        for dtype in DTYPES {
            check(dtype, &AttentionLayout::dense(2, 2, d, nq, nk), 43 + d as u64);
        }
    }
}

#[test]
fn scores_whose_maximum_jumps_between_chunks() {
    // Keys past 128 and past 400 score about 9 and 10 higher than those before them, more than
    // the matrix-unit kernel lets a row's exponent reference lag, so it rescales the output
    // accumulated so far (twice); the chunk and row-tile edges fall off those jumps.
    let gain = |t: usize| match t {
        0..128 => 0.1,
        128..400 => 3.0,
        _ => 6.0,
    };
    for dtype in DTYPES {
        for ctx in [ctx(), gpu_ctx()] {
            check_with_key_gain(&ctx, dtype, &AttentionLayout::dense(1, 2, 64, 70, 530), 90, gain);
        }
    }
}

/// The subgroup attention reading its operands as 32- and as 64-bit words (WD, which Mesa
/// 22's lavapipe takes), in both dtypes: self-attention over chunk and row-tile edges, and
/// cross-attention from a fused projection's strided columns. Up to 8 lanes a device without
/// 64-bit integers must be refused the words.
#[test]
fn subgroup_attention_reads_32_or_64_bit_words() {
    let ctx = ctx_with(GemmFamily::Subgroup);
    ctx.set_gpu_paths(false);
    ctx.choose(|c| c.quick_compile = false);
    let info = ctx.info().clone();
    assert!(info.subgroup_attention(false), "{} runs no subgroup attention", info.name);
    let mut strided = AttentionLayout::dense(2, 4, 64, 45, 77);
    (strided.k_ld, strided.v_ld, strided.k_batch, strided.v_batch) = (512, 512, 77 * 512, 77 * 512);
    strided.v_offset = 256;
    for words in [false, true] {
        ctx.choose(|c| c.word_loads = words);
        if words && !info.can_read_words() {
            assert!(!ctx.choices().word_loads, "word loads without shaderInt64 on {}", info.name);
            continue;
        }
        for dtype in DTYPES {
            for (i, l) in [AttentionLayout::dense(1, 4, 64, 70, 83), strided.clone()].iter().enumerate() {
                let (_, variants) = check_on(&ctx, dtype, l, 130 + i as u64);
                let read = |v: &&Variant| v.kernel == "attention" && v.param("WD") == Some(u32::from(words));
                let named: Vec<_> = variants.iter().map(|v| (v.kernel, v.params)).collect();
                assert!(variants.len() == 1 && variants.iter().all(read), "{named:?}");
            }
        }
    }
}

#[test]
fn quick_compiles_take_the_workgroup_attention() {
    // Where compiles are quick, attention with fewer than 256 channels takes attention_wg
    // (elsewhere the device's own choice); heads of 8 to 64, token counts off every tile.
    for (heads, d, nq, nk) in [(2, 8, 19, 23), (3, 24, 15, 9), (4, 40, 33, 77), (2, 64, 70, 70)] {
        for dtype in DTYPES {
            check_on(&quick_ctx(), dtype, &AttentionLayout::dense(2, heads, d, nq, nk), 60 + d as u64);
        }
    }
}

#[test]
fn strided_operands_from_a_fused_projection() {
    // Q, K, V as column blocks of [B, N, 3·H·D] projections (at column offsets 0, H·D and 2·H·D),
    // batch strides included.
    let (b, h, d, n) = (2, 3, 64, 70);
    let w = h * d;
    let mut l = AttentionLayout::dense(b, h, d, n, n);
    l.q_ld = 3 * w;
    l.k_ld = 3 * w;
    l.v_ld = 3 * w;
    l.q_batch = n * 3 * w;
    l.k_batch = n * 3 * w;
    l.v_batch = n * 3 * w;
    l.k_offset = w;
    l.v_offset = 2 * w;
    for dtype in DTYPES {
        check(dtype, &l, 50);
    }
}

#[test]
fn causal_self_attention_like_clip_text() {
    // 77 tokens (CLIP's context) over chunk and row-tile edges, plus a longer sequence.
    for (n, d) in [(77, 64), (150, 16)] {
        let mut l = AttentionLayout::dense(2, 2, d, n, n);
        l.causal = true;
        for dtype in DTYPES {
            check(dtype, &l, 60 + n as u64);
        }
    }
}

#[test]
fn head_sizes_and_strides_off_the_vec4_grid() {
    // 10 (a 40-wide encoder over 4 heads), 1, 3 and 33: padded by zeros into the vec4 kernel.
    for (d, nq, nk) in [(10, 17, 23), (1, 9, 5), (3, 20, 77), (33, 11, 13)] {
        for dtype in DTYPES {
            check(dtype, &AttentionLayout::dense(2, 4, d, nq, nk), 70 + d as u64);
        }
    }
    // A fused projection of odd width, causal, with an odd offset on every operand.
    let (b, h, d, n) = (2, 3, 5, 21);
    let w = h * d;
    let mut l = AttentionLayout::dense(b, h, d, n, n);
    (l.q_ld, l.k_ld, l.v_ld) = (3 * w + 1, 3 * w + 1, 3 * w + 1);
    (l.q_batch, l.k_batch, l.v_batch) = (n * (3 * w + 1), n * (3 * w + 1), n * (3 * w + 1));
    (l.q_offset, l.k_offset, l.v_offset) = (1, w + 1, 2 * w + 1);
    l.causal = true;
    for dtype in DTYPES {
        check(dtype, &l, 80);
    }
}

/// A fresh context on the device's paths or the GPU paths, with bindings of at most `limit`
/// bytes, so that wide heads run in several chunks of query rows.
fn limited_ctx(gpu_paths: bool, limit: u64) -> Context {
    let c = ctx_with(ctx().choices().gemm_family);
    c.set_gpu_paths(gpu_paths);
    c.choose(|c| c.binding_limit = limit);
    c
}

/// Whether `kernels` are attention as products: matrix products around a row softmax, no
/// flash kernel.
fn as_products(kernels: &[&str]) -> bool {
    kernels.contains(&"softmax") && !kernels.iter().any(|k| k.starts_with("attention"))
}

#[test]
fn wide_heads_run_as_products_in_chunks() {
    // The VAE's mid-block: one head of 512 over a fused [B, N, 3·512] projection, two images.
    // f32 products read it in place: 512 KiB bindings make chunks of 64 query rows (the last
    // one 20). f16 heads (an fp16-fix VAE) are widened into dense f32 rows, so the same bindings
    // hold all 84. Then two dense heads of 256, cross-attention: in f32, chunks of 128 rows and
    // a last one of 72 at 256 KiB; in f16, the same at 128 KiB.
    let (n, d) = (84, 512);
    let mut fused = AttentionLayout::dense(2, 1, d, n, n);
    (fused.q_ld, fused.k_ld, fused.v_ld) = (3 * d, 3 * d, 3 * d);
    (fused.q_batch, fused.k_batch, fused.v_batch) = (n * 3 * d, n * 3 * d, n * 3 * d);
    (fused.k_offset, fused.v_offset) = (d, 2 * d);
    let cross = AttentionLayout::dense(2, 2, 256, 200, 96);
    // (layout, dtype, binding limit, chunks per image and head)
    let cases = [
        (&fused, Dtype::F32, 512 << 10, 2),
        (&fused, Dtype::F16, 512 << 10, 1),
        (&cross, Dtype::F32, 256 << 10, 2),
        (&cross, Dtype::F16, 128 << 10, 2),
    ];
    for (seed, &(l, dtype, limit, chunks)) in cases.iter().enumerate() {
        for gpu_paths in [false, true] {
            let (kernels, _) = check_on(&limited_ctx(gpu_paths, limit), dtype, l, 100 + seed as u64);
            let count = |name: &str| kernels.iter().filter(|&&k| k == name).count();
            let what = format!("{dtype:?} d{}: {kernels:?}", l.head_dim);
            assert!(as_products(&kernels), "{what}");
            assert_eq!(count("softmax"), l.batch * l.heads * chunks, "{what}");
            // f16: keys and values widened once per image and head, queries once per chunk (each
            // copy in one or more bands), and each chunk's outputs narrowed back.
            let (widened, narrowed) = (count("copy_heads_to_f32"), count("copy_heads_from_f32"));
            match dtype {
                Dtype::F16 => assert!(
                    widened >= l.batch * l.heads * (2 + chunks) && narrowed >= l.batch * l.heads * chunks,
                    "{what}"
                ),
                Dtype::F32 => assert_eq!((widened, narrowed), (0, 0), "{what}"),
            }
        }
    }
}

#[test]
fn heads_the_products_do_not_take_stay_flash() {
    // Heads of 128, key counts or heads off the vec4 grid, causal masks: the flash kernels, on
    // both paths.
    let mut causal = AttentionLayout::dense(1, 1, 256, 40, 40);
    causal.causal = true;
    let cases = [
        (Dtype::F32, AttentionLayout::dense(1, 2, 128, 40, 32)),
        (Dtype::F16, AttentionLayout::dense(1, 2, 128, 40, 32)),
        (Dtype::F32, AttentionLayout::dense(1, 1, 512, 40, 30)),
        (Dtype::F16, AttentionLayout::dense(1, 1, 512, 40, 30)),
        (Dtype::F32, causal),
    ];
    for (i, (dtype, l)) in cases.into_iter().enumerate() {
        for ctx in [ctx(), gpu_ctx()] {
            let (kernels, _) = check_on(&ctx, dtype, &l, 110 + i as u64);
            assert!(kernels.len() == 1 && kernels[0].starts_with("attention"), "case {i}: {kernels:?}");
        }
    }
}
