//! `VK_NV_cooperative_matrix2`'s probe of attention (`bench kernels`) against the f64
//! softmax(QKᵀ)V on every attention tile the device runs; Mesa 26.1's lavapipe runs its
//! subgroup-scope tile, with the row reductions, per-element operations and conversions.

use super::attention::reference;
use vkdiff_runtime::ops::{attention, attention_cm2, AttentionLayout};
use vkdiff_runtime::{built_matrix2_tiles, Context, Dtype, Matrix2Probe, Matrix2Tile, ProbeChoice, Recorder};
use vkdiff_testkit::*;

/// Runs the probe on `tile` over random f16 Q, K, V laid out as `l` (output dense), key token t's
/// K values multiplied by `gain(t)`, and compares.
fn check(ctx: &Context, tile: &Matrix2Tile, l: &AttentionLayout, seed: u64, gain: impl Fn(usize) -> f32) {
    let extent =
        |off: usize, ld: usize, bs: usize, n: usize| off + (l.batch - 1) * bs + (n - 1) * ld + l.heads * l.head_dim;
    let q = stored(&random(extent(l.q_offset, l.q_ld, l.q_batch, l.q_tokens), seed), Dtype::F16);
    let mut k = random(extent(l.k_offset, l.k_ld, l.k_batch, l.kv_tokens), seed + 1);
    for (i, x) in k.iter_mut().enumerate().skip(l.k_offset) {
        *x *= gain((i - l.k_offset) % l.k_batch.max(1) / l.k_ld);
    }
    let k = stored(&k, Dtype::F16);
    let v = stored(&random(extent(l.v_offset, l.v_ld, l.v_batch, l.kv_tokens), seed + 2), Dtype::F16);
    let [tq, tk, tv] = [&q, &k, &v].map(|x| ctx.upload(&[x.len()], Dtype::F16, x).unwrap());
    let width = l.heads * l.head_dim;
    let out = ctx.zeros(&[l.batch, l.q_tokens, width], Dtype::F16).unwrap();
    let mut dense = l.clone();
    dense.o_ld = width;
    dense.o_batch = l.q_tokens * width;
    // Scores of O(4), as the attention tests take them: a wrong maximum or sum shows.
    let scale = 4.0 / (l.head_dim as f32).sqrt();
    ctx.run(|rec| attention_cm2(rec, [&tq, &tk, &tv], &out, &dense, scale, tile)).unwrap();
    let want = reference(&q, &k, &v, l, scale as f64);
    let what = format!(
        "attention_cm2 {}: b{} h{} d{} {}x{} causal {}",
        tile.label(),
        l.batch,
        l.heads,
        l.head_dim,
        l.q_tokens,
        l.kv_tokens,
        l.causal
    );
    assert_close(&what, &out.download().unwrap(), &want, 1e-3, storage_rtol(Dtype::F16));
}

#[test]
fn attention_cm2_matches_the_reference_on_every_tile_the_device_runs() {
    let ctx = ctx();
    let attention = |t: &Matrix2Tile| t.probe == Matrix2Probe::Attention;
    let tiles: Vec<Matrix2Tile> = ctx.info().matrix2_tiles().into_iter().filter(attention).collect();
    let lavapipe_26 = ctx.info().lavapipe_mesa.is_some_and(|v| v >= (26, 1));
    assert!(
        !(tiles.is_empty() && expect_cooperative() && lavapipe_26),
        "VKDIFF_EXPECT_COOPERATIVE=1 on Mesa 26.1's lavapipe, which offers the probe's operations: {:?}",
        ctx.info().cooperative_matrix2
    );
    let ones = |_: usize| 1.0;
    if tiles.is_empty() {
        let tile = built_matrix2_tiles(Matrix2Probe::Attention)[0];
        let t = ctx.zeros(&[64], Dtype::F16).unwrap();
        let mut rec = Recorder::new(&ctx, false).unwrap();
        let l = AttentionLayout::dense(1, 1, 16, 2, 2);
        let err = attention_cm2(&mut rec, [&t, &t, &t], &t, &l, 1.0, &tile).unwrap_err().to_string();
        assert!(err.contains("does not run the VK_NV_cooperative_matrix2 tile"), "{err}");
        return;
    }
    for tile in &tiles {
        let (rows, keys) = (tile.m as usize, tile.n as usize);
        // Self-attention over row-tile and chunk edges (whole chunks load in place, the last is
        // staged); cross-attention to CLIP's 77 tokens with heads narrower than the tile's (all
        // staged); two batches throughout.
        check(&ctx, tile, &AttentionLayout::dense(2, 2, 64, 2 * rows + 3, 3 * keys + 5), 11, ones);
        check(&ctx, tile, &AttentionLayout::dense(2, 3, 40, rows + 1, 77), 12, ones);
        // Keys whose scores jump up in later chunks: the running maximum moves and rescales O and
        // the row sums.
        let gain = |t: usize| {
            if t < keys {
                0.1
            } else if t < 3 * keys {
                3.0
            } else {
                6.0
            }
        };
        check(&ctx, tile, &AttentionLayout::dense(1, 2, 64, rows, 4 * keys + 7), 13, gain);
        // A causal mask (CLIP's text transformer), and Q, K, V as blocks of one fused projection.
        let mut causal = AttentionLayout::dense(2, 1, 32, 77, 77);
        causal.causal = true;
        check(&ctx, tile, &causal, 14, ones);
        let (h, d, n) = (2, 64, keys + rows + 1);
        let w = h * d;
        let mut fused = AttentionLayout::dense(2, h, d, n, n);
        (fused.q_ld, fused.k_ld, fused.v_ld) = (3 * w, 3 * w, 3 * w);
        (fused.q_batch, fused.k_batch, fused.v_batch) = (n * 3 * w, n * 3 * w, n * 3 * w);
        (fused.k_offset, fused.v_offset) = (w, 2 * w);
        check(&ctx, tile, &fused, 15, ones);
        // Offsets of 4 values: rows off the 16 bytes matrix loads need, so every chunk is staged.
        let mut shifted = AttentionLayout::dense(1, 2, 64, rows + 2, 2 * keys + 3);
        (shifted.q_offset, shifted.k_offset, shifted.v_offset) = (4, 4, 4);
        check(&ctx, tile, &shifted, 16, ones);
        // Heads past the tile's and f32 operands are refused before anything is recorded.
        let wide = AttentionLayout::dense(1, 1, tile.k as usize + 4, 2, 2);
        let t = ctx.zeros(&[4 * wide.head_dim], Dtype::F16).unwrap();
        let mut rec = Recorder::new(&ctx, false).unwrap();
        let err = attention_cm2(&mut rec, [&t, &t, &t], &t, &wide, 1.0, tile).unwrap_err().to_string();
        assert!(err.contains("heads of up to"), "{err}");
        let t32 = ctx.zeros(&[64], Dtype::F32).unwrap();
        let small = AttentionLayout::dense(1, 1, 16, 2, 2);
        let err = attention_cm2(&mut rec, [&t32, &t32, &t32], &t32, &small, 1.0, tile).unwrap_err().to_string();
        assert!(err.contains("must be f16"), "{err}");
    }
}

#[test]
fn attention_takes_the_probe_where_the_context_asks_for_it() {
    // A context of its own: the setting would reach other tests' attention in a shared one.
    let ctx = private_ctx();
    let offered = ctx.info().matrix2_tiles().iter().any(|t| t.probe == Matrix2Probe::Attention);
    let l = AttentionLayout::dense(2, 2, 64, 37, 77);
    let [q, k, v] = [11, 12, 13].map(|seed| stored(&random(2 * 77 * 128, seed), Dtype::F16));
    let [tq, tk, tv] = [&q, &k, &v].map(|x| ctx.upload(&[x.len()], Dtype::F16, x).unwrap());
    let out = ctx.zeros(&[2, 37, 128], Dtype::F16).unwrap();
    let want = reference(&q, &k, &v, &l, 0.125);
    for kernel in [ProbeChoice::Matrix2, ProbeChoice::Auto] {
        ctx.choose(|c| c.attention = kernel);
        let mut rec = Recorder::new(&ctx, true).unwrap();
        attention(&mut rec, &tq, &tk, &tv, &out, &l, 0.125).unwrap();
        let ran: Vec<&str> = rec.finish().unwrap().run_profiled().unwrap().iter().map(|t| t.kernel).collect();
        let what = format!("attention with {kernel:?}");
        assert_eq!(ran.contains(&"attention_cm2"), offered && kernel == ProbeChoice::Matrix2, "{what}: {ran:?}");
        assert_close(&what, &out.download().unwrap(), &want, 1e-3, storage_rtol(Dtype::F16));
    }
}
