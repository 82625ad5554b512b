//! conv2d (implicit GEMM, NHWC) against an f64 direct convolution.

use vkdiff_runtime::ops::{conv2d, oihw_to_ohwi, ConvParams, Padding};
use vkdiff_runtime::{Context, Dtype, GemmFamily, Variant};
use vkdiff_testkit::*;

pub(super) struct Case {
    pub(super) b: usize,
    pub(super) h: usize,
    pub(super) w: usize,
    pub(super) cin: usize,
    pub(super) cout: usize,
    /// Kernel height and width.
    pub(super) k: [usize; 2],
    pub(super) stride: usize,
    pub(super) pad: Padding,
    /// Adds into an output that already holds values (a fused residual).
    pub(super) accumulate: bool,
    /// max(·, 0) fused into the store.
    pub(super) relu: bool,
}

impl Case {
    /// The output's height and width.
    pub(super) fn out_size(&self) -> [usize; 2] {
        let [kh, kw] = self.k;
        [
            (self.h + self.pad.top + self.pad.bottom - kh) / self.stride + 1,
            (self.w + self.pad.left + self.pad.right - kw) / self.stride + 1,
        ]
    }
}

/// The direct convolution's kernels of `family`.
fn check(family: GemmFamily, dtype: Dtype, c: &Case, seed: u64) -> Vec<&'static Variant> {
    check_on(&direct(family), dtype, c, seed)
}

/// A context of `family` whose 3×3 convolutions run direct, not as Winograd's.
fn direct(family: GemmFamily) -> Context {
    let ctx = ctx_with(family);
    ctx.choose(|c| c.winograd_from = None);
    ctx
}

/// A CPU-family context whose 3×3 convolutions of stride 1 run as Winograd's F(2×2, 3×3),
/// however small.
pub(super) fn winograd() -> Context {
    let ctx = ctx_with(GemmFamily::Subgroup);
    ctx.choose(|c| c.winograd_from = Some(0));
    ctx
}

/// Runs the convolution on `ctx` against the reference, asserts the family it ran on, and
/// returns the product's variants.
pub(super) fn check_on(ctx: &Context, dtype: Dtype, c: &Case, seed: u64) -> Vec<&'static Variant> {
    let family = (ctx.choices().gemm_family, if ctx.choices().quick_compile { "quick" } else { "" });
    let ([kh, kw], [ho, wo]) = (c.k, c.out_size());
    let x = stored(&random(c.b * c.h * c.w * c.cin, seed), dtype);
    // Weights come as PyTorch stores them and are re-laid out, as the loaders will do.
    let w_oihw = stored(&random(c.cout * c.cin * kh * kw, seed + 1), dtype);
    let bias = stored(&random(c.cout, seed + 2), dtype);
    let tx = ctx.upload(&[c.b, c.h, c.w, c.cin], dtype, &x).unwrap();
    let tw = ctx.upload(&[c.cout, kh, kw, c.cin], dtype, &oihw_to_ohwi(&w_oihw, c.cout, c.cin, kh, kw)).unwrap();
    let tb = ctx.upload(&[c.cout], dtype, &bias).unwrap();
    let prior = if c.accumulate {
        stored(&random(c.b * ho * wo * c.cout, seed + 3), dtype)
    } else {
        vec![0.0; c.b * ho * wo * c.cout]
    };
    let out = ctx.upload(&[c.b, ho, wo, c.cout], dtype, &prior).unwrap();
    let params = ConvParams { stride: c.stride, pad: c.pad, accumulate: c.accumulate, relu: c.relu };
    let variants = ctx.run_listing(|rec| conv2d(rec, &tx, &tw, Some(&tb), &out, &params)).unwrap();
    let (want, mag) = reference(c, &x, &w_oihw, &bias, &prior);
    let rtol = storage_rtol(dtype);
    let what = format!(
        "{family:?} {dtype:?} {}x{}x{}x{} -> {} k{:?} s{} {:?} accumulate {} relu {}",
        c.b, c.h, c.w, c.cin, c.cout, c.k, c.stride, c.pad, c.accumulate, c.relu
    );
    // Same bound as GEMM: 1e-5 of Σ|x·w| for f32 accumulation, plus output storage rounding.
    // Winograd stores its transformed tiles and products in the dtype too: their rounding is
    // bounded by the storage's relative error of Σ|x·w|.
    let transformed = if variants.iter().any(|v| v.kernel == "winograd_input") { rtol } else { 0.0 };
    assert_within(&what, &out.download().unwrap(), &want, |i| {
        1e-6 + (1e-5 + transformed) * mag[i] + rtol * want[i].abs()
    });
    assert_product_family(ctx, dtype, &variants, &what, false)
}

/// The convolution in f64 (bias, then what `prior` held where the case accumulates, then ReLU
/// where it asks), and the sums of the magnitudes of its terms that bound its rounding.
pub(super) fn reference(c: &Case, x: &[f32], w_oihw: &[f32], bias: &[f32], prior: &[f32]) -> (Vec<f64>, Vec<f64>) {
    let ([kh, kw], [ho, wo]) = (c.k, c.out_size());
    let mut want = vec![0.0f64; c.b * ho * wo * c.cout];
    let mut mag = vec![0.0f64; want.len()];
    for n in 0..c.b {
        for oy in 0..ho {
            for ox in 0..wo {
                for o in 0..c.cout {
                    let before = prior[((n * ho + oy) * wo + ox) * c.cout + o] as f64;
                    let (mut acc, mut abs) = (bias[o] as f64 + before, bias[o].abs() as f64 + before.abs());
                    for ky in 0..kh {
                        for kx in 0..kw {
                            let iy = (oy * c.stride + ky) as isize - c.pad.top as isize;
                            let ix = (ox * c.stride + kx) as isize - c.pad.left as isize;
                            if iy < 0 || ix < 0 || iy >= c.h as isize || ix >= c.w as isize {
                                continue;
                            }
                            for i in 0..c.cin {
                                let xv = x[((n * c.h + iy as usize) * c.w + ix as usize) * c.cin + i] as f64;
                                let wv = w_oihw[((o * c.cin + i) * kh + ky) * kw + kx] as f64;
                                acc += xv * wv;
                                abs += (xv * wv).abs();
                            }
                        }
                    }
                    let at = ((n * ho + oy) * wo + ox) * c.cout + o;
                    want[at] = if c.relu { acc.max(0.0) } else { acc };
                    mag[at] = abs;
                }
            }
        }
    }
    (want, mag)
}

/// Every family and dtype (the matrix units in both workgroup tiles), and Winograd's F(2×2, 3×3)
/// where the case is a 3×3 convolution of stride 1; returns each direct run's variants.
fn all(c: Case, seed: u64) -> Vec<(GemmFamily, Vec<&'static Variant>)> {
    let mut ran = Vec::new();
    for family in [GemmFamily::Subgroup, GemmFamily::Tiled] {
        for dtype in DTYPES {
            ran.push((family, check(family, dtype, &c, seed)));
        }
    }
    if c.k == [3, 3] && c.stride == 1 {
        for dtype in DTYPES {
            check_on(&winograd(), dtype, &c, seed);
        }
    }
    // On the matrix units, in both workgroup tiles.
    for ctx in cooperative_ctxs() {
        for dtype in DTYPES {
            ran.push((GemmFamily::Cooperative, check_on(&ctx, dtype, &c, seed)));
        }
    }
    ran
}

fn params_of(ran: &[(GemmFamily, Vec<&'static Variant>)], family: GemmFamily, kernel: &str, param: &str) -> Vec<u32> {
    ran.iter()
        .filter(|(f, _)| *f == family)
        .flat_map(|(_, v)| v.iter().filter(|v| v.kernel == kernel).filter_map(|v| v.param(param)))
        .collect()
}

/// The subgroup kernels reading their operands as 32- and as 64-bit words, and the weights
/// from storage and from texels, where the device takes them (gemm.rs holds the refusals):
/// padding and a residual, both dtypes against f64.
#[test]
fn subgroup_kernels_read_32_or_64_bit_words_from_storage_or_texels() {
    let ctx = direct(GemmFamily::Subgroup);
    let c = padded_residual();
    for (words, texels) in [(false, false), (true, false), (false, true), (true, true)] {
        ctx.choose(|c| (c.word_loads, c.texel_reads) = (words, texels));
        let (wd, tb) = (u32::from(ctx.choices().word_loads), u32::from(ctx.choices().texel_reads));
        for dtype in DTYPES {
            let ran = check_on(&ctx, dtype, &c, 31);
            let read = |v: &&Variant| v.kernel == "conv_sg" && v.param("WD") == Some(wd) && v.param("TB") == Some(tb);
            assert!(
                !ran.is_empty() && ran.iter().all(read),
                "{:?}",
                ran.iter().map(|v| (v.kernel, v.params)).collect::<Vec<_>>()
            );
        }
    }
}

/// A 3×3 convolution with padding 1 onto a residual.
fn padded_residual() -> Case {
    Case {
        b: 2,
        h: 9,
        w: 7,
        cin: 16,
        cout: 24,
        k: [3, 3],
        stride: 1,
        pad: Padding::same(1),
        accumulate: true,
        relu: false,
    }
}

#[test]
fn conv3x3_stride1_pad1() {
    all(padded_residual(), 21);
}

#[test]
fn conv3x3_stride2_pad1() {
    all(
        Case {
            b: 1,
            h: 10,
            w: 12,
            cin: 8,
            cout: 36,
            k: [3, 3],
            stride: 2,
            pad: Padding::same(1),
            accumulate: false,
            relu: false,
        },
        22,
    );
}

#[test]
fn conv3x3_stride2_vae_padding() {
    // diffusers' VAE Downsample2D pads (0, 1, 0, 1) then convolves with stride 2, no padding.
    let pad = Padding { top: 0, left: 0, bottom: 1, right: 1 };
    all(Case { b: 1, h: 8, w: 8, cin: 12, cout: 8, k: [3, 3], stride: 2, pad, accumulate: false, relu: false }, 23);
}

/// The eight-subgroup tiles of 2×2-fragment subgroups (128×64 and 64×128 at 16×16×16), which
/// [`cooperative_ctxs`] leaves out: padding, stride 2, the VAE's one-sided padding, a residual
/// with ReLU over pixels and channels off the tiles' multiples, and K-steps across taps.
#[test]
fn conv_eight_subgroup_tiles_of_two_by_two_fragments() {
    use vkdiff_runtime::MatrixTile;
    let same = Padding::same(1);
    let vae = Padding { top: 0, left: 0, bottom: 1, right: 1 };
    let case = |b, h, w, cin, cout, stride, pad, residual| Case {
        b,
        h,
        w,
        cin,
        cout,
        k: [3, 3],
        stride,
        pad,
        accumulate: residual,
        relu: residual,
    };
    for ctx in cooperative_ctxs_on(&[MatrixTile::EightTall, MatrixTile::EightWide]) {
        for (c, seed) in [
            (case(2, 9, 7, 16, 24, 1, same, true), 21),
            (case(1, 10, 12, 8, 36, 2, same, false), 22),
            (case(1, 8, 8, 12, 8, 2, vae, false), 23),
            (case(1, 13, 11, 40, 72, 1, same, true), 24),
        ] {
            check_on(&ctx, Dtype::F16, &c, seed);
        }
    }
}

#[test]
fn conv_large_products_take_the_large_tiles() {
    // 66·66 = 4356 output pixels × 132 channels: over 128 tiles of 64 (lavapipe's 8×8 fragments);
    // two images: over 128 tiles of 128, the tiled kernel's 128-row tiles.
    for (b, seed) in [(1, 28), (2, 29)] {
        let ran = all(
            Case {
                b,
                h: 66,
                w: 66,
                cin: 4,
                cout: 132,
                k: [3, 3],
                stride: 1,
                pad: Padding::same(1),
                accumulate: true,
                relu: true,
            },
            seed,
        );
        let rows = params_of(&ran, GemmFamily::Tiled, "conv_tiled_v4", "RH");
        assert!(rows.iter().all(|&rh| rh == b as u32), "{b} images: RH {rows:?}");
    }
}

#[test]
fn conv_large_images_take_the_large_row_tiles() {
    // 34×34 = 1156 and 2·13·13 = 338 output pixels select the tallest and the 32-row variants
    // where the weights number at least 2¹⁷ (3·3·128·116; smaller convolutions take 16 rows).
    let ran = all(
        Case {
            b: 1,
            h: 34,
            w: 34,
            cin: 128,
            cout: 116,
            k: [3, 3],
            stride: 1,
            pad: Padding::same(1),
            accumulate: false,
            relu: false,
        },
        26,
    );
    let tallest = crate::tallest_subgroup_rows();
    assert_eq!(params_of(&ran, GemmFamily::Subgroup, "conv_sg", "TM"), [tallest; 2], "1156 pixels: {tallest} rows");
    let ran = all(
        Case {
            b: 2,
            h: 13,
            w: 13,
            cin: 128,
            cout: 116,
            k: [3, 3],
            stride: 1,
            pad: Padding::same(1),
            accumulate: false,
            relu: false,
        },
        27,
    );
    assert_eq!(params_of(&ran, GemmFamily::Subgroup, "conv_sg", "TM"), [32, 32], "338 pixels: 32 rows");
}

#[test]
fn conv_quick_compiles_take_the_eight_row_tiles() {
    // Where compiles are quick, convolutions with fewer than 2¹⁷ weights take the 8-row
    // subgroup variants (elsewhere the family the device has); 2·7·9 output pixels.
    let case = Case {
        b: 2,
        h: 7,
        w: 9,
        cin: 12,
        cout: 16,
        k: [3, 3],
        stride: 1,
        pad: Padding::same(1),
        accumulate: true,
        relu: false,
    };
    for dtype in DTYPES {
        let ctx = quick_ctx();
        let ran = check_on(&ctx, dtype, &case, 29);
        if ctx.choices().gemm_family == GemmFamily::Subgroup {
            assert!(ran.iter().all(|v| v.param("TM") == Some(8)), "the quick 8-row variants");
        }
    }
}

#[test]
fn conv1x1() {
    all(
        Case {
            b: 2,
            h: 6,
            w: 5,
            cin: 40,
            cout: 20,
            k: [1, 1],
            stride: 1,
            pad: Padding::same(0),
            accumulate: true,
            relu: false,
        },
        24,
    );
}

#[test]
fn conv_channels_off_the_vec4_grid_are_padded() {
    // Cin = 3 into 5 channels, accumulating; 8 into 3 with ReLU (the VAE's conv_out, 128 → 3);
    // 3 into 8 at stride 2 (an encoder's conv_in, ControlNet's hint): zero channels padded on.
    let case = |cin, cout, stride, accumulate, relu| Case {
        b: 2,
        h: 7,
        w: 6,
        cin,
        cout,
        k: [3, 3],
        stride,
        pad: Padding::same(1),
        accumulate,
        relu,
    };
    for (seed, c) in
        [case(3, 5, 1, true, false), case(8, 3, 1, false, true), case(3, 8, 2, false, false)].into_iter().enumerate()
    {
        all(c, 25 + seed as u64);
    }
}

#[test]
fn conv_asymmetric_kernels_with_relu() {
    // Inception's factorised 1×7 / 7×1 and 1×3 / 3×1 convolutions, each followed by ReLU.
    let pad = |y, x| Padding { top: y, left: x, bottom: y, right: x };
    all(
        Case {
            b: 2,
            h: 9,
            w: 8,
            cin: 12,
            cout: 16,
            k: [1, 7],
            stride: 1,
            pad: pad(0, 3),
            accumulate: false,
            relu: true,
        },
        28,
    );
    all(
        Case {
            b: 1,
            h: 9,
            w: 8,
            cin: 12,
            cout: 16,
            k: [7, 1],
            stride: 1,
            pad: pad(3, 0),
            accumulate: true,
            relu: true,
        },
        29,
    );
    all(
        Case {
            b: 1,
            h: 11,
            w: 10,
            cin: 3,
            cout: 8,
            k: [3, 3],
            stride: 2,
            pad: pad(0, 0),
            accumulate: false,
            relu: true,
        },
        30,
    );
}
