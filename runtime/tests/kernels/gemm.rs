//! GEMM / linear against an f64 reference, for both kernel families and both storage dtypes.

use vkdiff_runtime::ops::{linear, linear_geglu, matmul, Matmul, GEGLU_COLUMNS};
use vkdiff_runtime::{Arena, Context, Dtype, GemmFamily, Variant};
use vkdiff_testkit::*;

/// Reference C and Σ|a·b| per element (the scale that bounds rounding error of a dot product).
fn reference(a: &[f32], b: &[f32], bias: Option<&[f32]>, c0: &[f32], s: &Matmul) -> (Vec<f64>, Vec<f64>) {
    let mut c = vec![0.0; c0.len()];
    let mut mag = vec![0.0; c0.len()];
    for bi in 0..s.batch {
        for i in 0..s.m {
            for j in 0..s.n {
                let (mut acc, mut abs) = (0.0f64, 0.0f64);
                for k in 0..s.k {
                    let av = a[bi * s.a_batch + i * s.lda + k] as f64;
                    let bv = if s.b_transposed {
                        b[bi * s.b_batch + j * s.ldb + k]
                    } else {
                        b[bi * s.b_batch + k * s.ldb + j]
                    } as f64;
                    acc += av * bv;
                    abs += (av * bv).abs();
                }
                let at = bi * s.c_batch + i * s.ldc + j;
                let mut v = s.alpha as f64 * acc + bias.map_or(0.0, |b| b[j] as f64);
                if s.accumulate {
                    v += c0[at] as f64;
                }
                c[at] = v;
                mag[at] = s.alpha.abs() as f64 * abs + v.abs();
            }
        }
    }
    (c, mag)
}

/// Accumulation error per unit of Σ|a·b|: f32 sums of up to ~2k terms stay well under 1e-5.
fn accumulation_tol() -> f64 {
    1e-5
}

fn check(family: GemmFamily, dtype: Dtype, s: &Matmul, with_bias: bool, seed: u64) -> Vec<&'static Variant> {
    check_on(&ctx_with(family), dtype, s, with_bias, seed)
}

/// Runs the product on `ctx` against the reference, asserts the family it ran on (a shape off
/// the vec4 grid may fall back to the tiled kernel), and returns the product's variants.
fn check_on(ctx: &Context, dtype: Dtype, s: &Matmul, with_bias: bool, seed: u64) -> Vec<&'static Variant> {
    check_with_operands_at(ctx, dtype, s, (with_bias, seed), 0)
}

/// As [`check_on`], with A and B views that start `start` elements into their buffers.
fn check_with_operands_at(
    ctx: &Context,
    dtype: Dtype,
    s: &Matmul,
    (with_bias, seed): (bool, u64),
    start: usize,
) -> Vec<&'static Variant> {
    let family = (ctx.choices().gemm_family, if ctx.choices().quick_compile { "quick" } else { "" });
    let (b_rows, b_cols) = if s.b_transposed { (s.n, s.k) } else { (s.k, s.n) };
    let a_len = (s.batch - 1) * s.a_batch + (s.m - 1) * s.lda + s.k;
    let b_len = (s.batch - 1) * s.b_batch + (b_rows - 1) * s.ldb + b_cols;
    let c_len = (s.batch - 1) * s.c_batch + (s.m - 1) * s.ldc + s.n;
    let a = stored(&random(a_len, seed), dtype);
    let b = stored(&random(b_len, seed + 1), dtype);
    let bias = stored(&random(s.n, seed + 2), dtype);
    let c0 = stored(&random(c_len, seed + 3), dtype);
    let view = |values: &[f32]| {
        let padded: Vec<f32> = std::iter::repeat_n(f32::NAN, start).chain(values.iter().copied()).collect();
        ctx.upload(&[start + values.len()], dtype, &padded).unwrap().narrow(start, values.len()).unwrap()
    };
    let (ta, tb) = (view(&a), view(&b));
    let tbias = ctx.upload(&[s.n], dtype, &bias).unwrap();
    let tc = ctx.upload(&[c_len], dtype, &c0).unwrap();
    let variants = ctx.run_listing(|rec| matmul(rec, &ta, &tb, with_bias.then_some(&tbias), &tc, s)).unwrap();
    let got = tc.download().unwrap();
    let (want, mag) = reference(&a, &b, with_bias.then_some(&bias[..]), &c0, s);
    // Elements the product does not cover (strided C) must be untouched.
    let want: Vec<f64> =
        want.iter().zip(&c0).zip(&mag).map(|((&w, &c), &m)| if m == 0.0 { c as f64 } else { w }).collect();
    let rtol = storage_rtol(dtype);
    let what = format!("{family:?} {dtype:?} {s:?}");
    assert_within(&what, &got, &want, |i| 1e-6 + accumulation_tol() * mag[i] + rtol * want[i].abs());
    let off_grid = !(s.n.is_multiple_of(4) && s.k.is_multiple_of(4));
    assert_product_family(ctx, dtype, &variants, &what, off_grid)
}

/// Every family and dtype; returns each run's product variants with its family and dtype.
/// On the matrix units, in both workgroup tiles ([`cooperative_ctxs`]).
fn both(s: Matmul, bias: bool, seed: u64) -> Vec<(GemmFamily, Dtype, Vec<&'static Variant>)> {
    let mut ran = Vec::new();
    for family in [GemmFamily::Subgroup, GemmFamily::Tiled] {
        for dtype in DTYPES {
            ran.push((family, dtype, check(family, dtype, &s, bias, seed)));
        }
    }
    for ctx in cooperative_ctxs() {
        for dtype in DTYPES {
            ran.push((GemmFamily::Cooperative, dtype, check_on(&ctx, dtype, &s, bias, seed)));
        }
    }
    ran
}

/// The values of `param` of the variants `family` ran (in `dtype`, or any dtype).
fn params_of(
    ran: &[(GemmFamily, Dtype, Vec<&'static Variant>)],
    family: GemmFamily,
    kernel: &str,
    param: &str,
) -> Vec<u32> {
    ran.iter()
        .filter(|(f, _, _)| *f == family)
        .flat_map(|(_, _, v)| v.iter().filter(|v| v.kernel == kernel).filter_map(|v| v.param(param)))
        .collect()
}

#[test]
fn square_and_rectangular() {
    both(Matmul::dense(64, 64, 64, false), false, 1);
    both(Matmul::dense(130, 72, 36, false), true, 2);
    both(Matmul::dense(33, 200, 516, true), true, 3);
}

/// The eight-subgroup tiles of 2×2-fragment subgroups (128×64 and 64×128 at 16×16×16), which
/// [`cooperative_ctxs`] leaves out: M, N and K off their multiples (a last, partial K-step after
/// full ones), B stored either way, batches with strides, alpha and a residual, and GEGLU's
/// fused projection; each asserted to run in its tile where it is built for the device's fragment.
#[test]
fn eight_subgroup_tiles_of_two_by_two_fragments() {
    use vkdiff_runtime::MatrixTile;
    for ctx in cooperative_ctxs_on(&[MatrixTile::EightTall, MatrixTile::EightWide]) {
        for (s, bias, seed) in [
            (Matmul::dense(130, 72, 36, false), true, 2),
            (Matmul::dense(33, 200, 516, true), true, 3),
            (Matmul::dense(150, 136, 136, true), false, 4),
            (batched_strided(), true, 6),
        ] {
            check_on(&ctx, Dtype::F16, &s, bias, seed);
        }
        check_linear_geglu(&ctx, Dtype::F16, (130, 24, 6 * GEGLU_COLUMNS), true, 20);
    }
}

#[test]
fn tall_shapes_take_the_large_row_tiles() {
    // M ≥ 256 and ≥ 512 select the 32-row and the tallest subgroup variants for products of at
    // least 2¹⁷ weights (smaller ones take 16 rows); M off their multiples. The tallest, with B
    // stored N×K as linear layers store it, at a K that ends half-way through a turn of four steps
    // (8 lanes: 64 rows) and at the end of one of two (16 lanes: 128 rows).
    let ran = both(Matmul::dense(300, 516, 256, true), true, 8);
    assert_eq!(params_of(&ran, GemmFamily::Subgroup, "gemm_sg", "TM"), [32, 32], "M ≥ 256: 32 rows");
    let tallest = crate::tallest_subgroup_rows();
    for (s, seed) in [(Matmul::dense(1030, 520, 256, false), 9), (Matmul::dense(1030, 520, 264, true), 17)] {
        let ran = both(s.clone(), false, seed);
        assert_eq!(params_of(&ran, GemmFamily::Subgroup, "gemm_sg", "TM"), [tallest; 2], "{s:?}: {tallest} rows");
    }
}

#[test]
fn quick_compiles_take_the_eight_row_tiles() {
    // Where compiles are quick, products with fewer than 2¹⁷ weights or at most 8 rows take the
    // 8-row subgroup variants (elsewhere the family the device has); M off multiples of 8.
    let ctx = quick_ctx();
    for (s, seed) in [
        (Matmul::dense(37, 68, 36, true), 12),
        (Matmul::dense(300, 40, 44, false), 13),
        (Matmul::dense(5, 520, 260, true), 14),
        (Matmul::dense(3, 260, 520, false), 15),
    ] {
        for dtype in DTYPES {
            let ran = check_on(&ctx, dtype, &s, true, seed);
            if ctx.choices().gemm_family == GemmFamily::Subgroup {
                let rows: Vec<Option<u32>> = ran.iter().map(|v| v.param("TM")).collect();
                assert!(rows.iter().all(|&r| r == Some(8)), "{s:?}: the quick 8-row variants, not {rows:?}");
            }
        }
    }
}

#[test]
fn large_products_take_the_large_tiles() {
    // At least 128 tiles of 8·FM × 8·FN (64 on lavapipe, 128 on NVIDIA/AMD) select 4×4 fragments
    // per subgroup where such a variant is built and the sums fit (CPU devices, 64-lane GPUs;
    // 32-lane GPUs and Intel's shapes keep 2×2); at least 128 of 128×128, the tiled kernel's
    // 128-row tiles (the first product; the second takes 64 rows); M, N and K off every tile's
    // multiple. The matrix units read K = 36 in units of 4, the others in units of 8.
    let ran = both(Matmul::dense(1030, 2052, 24, true), true, 10);
    assert!(params_of(&ran, GemmFamily::Tiled, "gemm_tiled_v4", "RH").iter().all(|&rh| rh == 2), "128-row tiles");
    let ran = both(Matmul::dense(520, 1000, 40, false), false, 11);
    assert!(params_of(&ran, GemmFamily::Tiled, "gemm_tiled_v4", "RH").iter().all(|&rh| rh == 1), "64-row tiles");
    let ran = both(Matmul::dense(1030, 2052, 36, true), false, 16);
    // K = 36 is no multiple of 8: the matrix units read it in units of 4.
    assert!(params_of(&ran, GemmFamily::Cooperative, "gemm_coop", "UW").iter().all(|&uw| uw == 4));
    // In workgroups of four subgroups (2×2).
    let four = |v: &&&Variant| v.kernel == "gemm_coop" && [v.param("GM"), v.param("GN")] == [Some(2); 2];
    let coop: Vec<(Option<u32>, Option<u32>)> = ran
        .iter()
        .filter(|(f, _, _)| *f == GemmFamily::Cooperative)
        .flat_map(|(_, _, v)| v.iter().filter(four))
        .map(|v| (v.param("WM"), v.param("WN")))
        .collect();
    if ctx().info().cooperative_variant().is_some_and(|f| f.lanes != 32 && f.m == f.n && f.n == f.k) {
        assert!(
            !coop.is_empty() && coop.iter().all(|&w| w == (Some(4), Some(4))),
            "4×4 fragments where built: {coop:?}"
        );
    }
}

#[test]
fn shapes_off_the_vec4_grid() {
    // N, K not multiples of 4: the subgroup family must fall back to the tiled kernel.
    both(Matmul::dense(17, 13, 27, false), true, 4);
    both(Matmul::dense(5, 3, 7, true), false, 5);
}

/// Three products whose A and C rows and batches are strided, scaled by alpha and added to
/// what C holds.
fn batched_strided() -> Matmul {
    let mut s = Matmul::dense(40, 24, 32, false);
    s.batch = 3;
    s.lda = 36;
    s.a_batch = 40 * 36 + 4;
    s.b_batch = 32 * 24;
    s.ldc = 28;
    s.c_batch = 40 * 28 + 8;
    s.alpha = 0.37;
    s.accumulate = true;
    s
}

#[test]
fn batched_strided_alpha_accumulate() {
    let mut s = batched_strided();
    both(s.clone(), true, 6);
    s.b_transposed = true;
    s.ldb = 32;
    s.b_batch = 0;
    both(s, false, 7);
    // N and ldc off the vec4 grid: the scalar tiled kernel, whose store is its own, scales and
    // accumulates too (a planted error that dropped its alpha passed every test before this).
    let mut odd = Matmul::dense(40, 23, 32, false);
    odd.batch = 2;
    odd.ldc = 27;
    odd.c_batch = 40 * 27 + 3;
    odd.alpha = 0.37;
    odd.accumulate = true;
    let ran = both(odd, true, 8);
    let tiled: Vec<&str> = ran
        .iter()
        .filter(|(f, _, _)| *f == GemmFamily::Tiled)
        .flat_map(|(_, _, v)| v.iter().map(|v| v.kernel))
        .collect();
    assert!(tiled.iter().all(|&k| k == "gemm_tiled") && !tiled.is_empty(), "{tiled:?}");
}

/// The subgroup kernels reading their operands as 32- and as 64-bit words (WD), and from storage
/// and from texels (TB), as lavapipe before Mesa 26 takes both, in both dtypes against f64: B
/// stored K×N and N×K, batched and strided, A and B as views past the start of their buffers,
/// and GEGLU fused. From texels f32 products read A and B (TA); f16 ones read both as eight-half
/// texels where B is stored N×K and K and the strides are multiples of 8, else from storage,
/// and B alone where B is stored K×N. Up to 8 lanes a device without 64-bit integers must be
/// refused the words, and one that fetches no texels the texels.
#[test]
fn subgroup_kernels_read_32_or_64_bit_words_from_storage_or_texels() {
    let ctx = ctx_with(GemmFamily::Subgroup);
    let info = ctx.info().clone();
    assert!(info.gemm_subgroup_width().is_some(), "{} runs no subgroup-register kernel", info.name);
    // A and B a whole binding alignment into their buffers (the texel views' start).
    let start = |dtype: Dtype| info.binding_alignment() as usize / if dtype == Dtype::F16 { 2 } else { 4 };
    // Each product, and what its f16 variant reads from texels: (TB, TA).
    let (b_only, both, none) = ((Some(1), None), (Some(1), Some(1)), (Some(0), None));
    let products = [
        (Matmul::dense(70, 96, 40, false), b_only),
        (Matmul::dense(37, 64, 56, true), both),
        (Matmul::dense(37, 64, 52, true), none),
        (batched_strided(), b_only),
    ];
    for (words, texels) in [(false, false), (true, false), (false, true), (true, true)] {
        // The 16-row variants, whose turns have pairs of steps.
        ctx.choose(|c| (c.word_loads, c.texel_reads, c.quick_compile) = (words, texels, false));
        if words && !info.can_read_words() {
            assert!(!ctx.choices().word_loads, "word loads without shaderInt64 on {}", info.name);
            continue;
        }
        if texels && !info.reads_texels() {
            assert!(!ctx.choices().texel_reads, "texels where {} fetches none", info.name);
            continue;
        }
        for dtype in DTYPES {
            for (s, f16_reads) in &products {
                let ran = check_with_operands_at(&ctx, dtype, s, (true, 41), start(dtype));
                let reads = match (texels, dtype) {
                    (false, _) => none,
                    (true, Dtype::F32) => both,
                    (true, Dtype::F16) => *f16_reads,
                };
                let read = |v: &&Variant| {
                    v.kernel == "gemm_sg"
                        && v.param("WD") == Some(u32::from(words))
                        && (v.param("TB"), v.param("TA")) == reads
                };
                assert!(
                    !ran.is_empty() && ran.iter().all(read),
                    "{dtype:?} {s:?}: {:?}",
                    ran.iter().map(|v| (v.kernel, v.params)).collect::<Vec<_>>()
                );
            }
            check_linear_geglu(&ctx, dtype, (37, 64, 64 * GEGLU_COLUMNS), true, 44);
        }
    }
}

#[test]
fn linear_layer_shapes() {
    for dtype in DTYPES {
        let ctx = ctx();
        let (rows, k, n) = (2 * 77, 64, 96);
        let x = stored(&random(rows * k, 11), dtype);
        let w = stored(&random(n * k, 12), dtype);
        let bias = stored(&random(n, 13), dtype);
        let tx = ctx.upload(&[2, 77, k], dtype, &x).unwrap();
        let tw = ctx.upload(&[n, k], dtype, &w).unwrap();
        let tb = ctx.upload(&[n], dtype, &bias).unwrap();
        let out = ctx.zeros(&[2, 77, n], dtype).unwrap();
        ctx.run(|rec| linear(rec, &tx, &tw, Some(&tb), &out)).unwrap();
        let s = Matmul::dense(rows, n, k, true);
        let (want, mag) = reference(&x, &w, Some(&bias), &vec![0.0; rows * n], &s);
        let rtol = storage_rtol(dtype);
        assert_within(&format!("linear {dtype:?}"), &out.download().unwrap(), &want, |i| {
            1e-6 + accumulation_tol() * mag[i] + rtol * want[i].abs()
        });
    }
}

/// linear_geglu on one family against the f64 projection followed by GEGLU (value first).
/// `linear_geglu` (`fused`: the fused product itself, whichever way the op would go).
fn check_linear_geglu(ctx: &Context, dtype: Dtype, (rows, k, n): (usize, usize, usize), fused: bool, seed: u64) {
    let f = n / 2;
    let x = stored(&random(rows * k, seed), dtype);
    let w = stored(&random(n * k, seed + 1), dtype);
    let bias = stored(&random(n, seed + 2), dtype);
    let tx = ctx.upload(&[rows, k], dtype, &x).unwrap();
    let tw = ctx.upload(&[n, k], dtype, &w).unwrap();
    let tb = ctx.upload(&[n], dtype, &bias).unwrap();
    let out = ctx.zeros(&[rows, f], dtype).unwrap();
    if fused {
        ctx.run(|rec| matmul(rec, &tx, &tw, Some(&tb), &out, &Matmul::linear_geglu(rows, n, k))).unwrap();
    } else {
        let scratch = Arena::new(ctx);
        ctx.run(|rec| linear_geglu(rec, (&tx, &tw, Some(&tb)), &out, &scratch)).unwrap();
    }
    let (y, mag) = reference(&x, &w, Some(&bias), &vec![0.0; rows * n], &Matmul::dense(rows, n, k, true));
    let gelu = |g: f64| 0.5 * g * (1.0 + libm::erf(g / 2f64.sqrt()));
    let at = |i: usize| (i / f * n + i % f, i / f * n + f + i % f);
    let want: Vec<f64> = (0..rows * f).map(|i| y[at(i).0] * gelu(y[at(i).1])).collect();
    let rtol = storage_rtol(dtype);
    // Each input's error (its sum's, and its f16 rounding where the projection is stored),
    // through the product (|GELU'| < 1.13), plus the output's rounding.
    assert_within(
        &format!(
            "linear_geglu {:?} quick={} fused={fused} {dtype:?} {rows}×{k}→{n}",
            ctx.choices().gemm_family,
            ctx.choices().quick_compile
        ),
        &out.download().unwrap(),
        &want,
        |i| {
            let ((v, g), (mv, mg)) = ((y[at(i).0], y[at(i).1]), (mag[at(i).0], mag[at(i).1]));
            let (ev, eg) = (accumulation_tol() * mv + rtol * v.abs(), accumulation_tol() * mg + rtol * g.abs());
            1e-6 + ev * gelu(g).abs() + 1.13 * v.abs() * eg + rtol * want[i].abs()
        },
    );
}

#[test]
fn linear_geglu_fused_into_the_product() {
    // Every family's fused product where N is a multiple of GEGLU_COLUMNS (32), and the op, which
    // fuses on the subgroup kernels only (M and N off the tiles' multiples; K = 27 takes the tiled
    // kernel, and 130×2752 the cooperative kernels' large tiles); N = 40 goes through the GEGLU
    // kernel, as do products of fewer than 2¹⁷ weights (all but 64→2048) and every width where
    // the context prefers quick compiles. Rows stay under 256, so the subgroup kernels compile
    // at 16 rows only.
    // The matrix units in both workgroup tiles.
    let c = GEGLU_COLUMNS;
    let mut contexts = vec![ctx_with(GemmFamily::Subgroup), ctx_with(GemmFamily::Tiled)];
    contexts.extend(cooperative_ctxs());
    for (ctx, quick) in contexts.iter().flat_map(|ctx| [(ctx, false), (ctx, true)]) {
        ctx.choose(|c| c.quick_compile = quick);
        for dtype in DTYPES {
            for (i, shape) in [
                (37, 40, 2 * c),
                (37, 64, 64 * c),
                (2 * 77, 64, 3 * c),
                (9, 27, 2 * c),
                (130, 24, 86 * c),
                (5, 12, c + 8),
            ]
            .into_iter()
            .enumerate()
            {
                check_linear_geglu(ctx, dtype, shape, false, 20 + 3 * i as u64);
                if shape.2 % c == 0 {
                    check_linear_geglu(ctx, dtype, shape, true, 20 + 3 * i as u64);
                }
            }
        }
    }
}

#[test]
fn geglu_refuses_what_it_cannot_pair() {
    let ctx = ctx();
    let (x, w) = (ctx.zeros(&[4, 8], Dtype::F32).unwrap(), ctx.zeros(&[64, 8], Dtype::F32).unwrap());
    let out = ctx.zeros(&[4, 32], Dtype::F32).unwrap();
    let mut s = Matmul::linear_geglu(4, 64, 8);
    s.accumulate = true;
    let err = ctx.run(|rec| matmul(rec, &x, &w, None, &out, &s)).unwrap_err().to_string();
    assert!(err.contains("GEGLU needs"), "{err}");
    let odd = ctx.zeros(&[4, 31], Dtype::F32).unwrap();
    let err = ctx.run(|rec| linear_geglu(rec, (&x, &w, None), &odd, &Arena::new(&ctx))).unwrap_err().to_string();
    assert!(err.contains("is not 4×32"), "{err}");
}

#[test]
fn wrong_shapes_are_errors() {
    let ctx = ctx();
    let x = ctx.zeros(&[4, 8], Dtype::F32).unwrap();
    let w = ctx.zeros(&[6, 7], Dtype::F32).unwrap();
    let out = ctx.zeros(&[4, 6], Dtype::F32).unwrap();
    let err = ctx.run(|rec| linear(rec, &x, &w, None, &out)).unwrap_err().to_string();
    assert!(err.contains("does not end in 7"), "{err}");
}
