//! `bench kernels`' cases: each kernel on SDXL-sized shapes, with the work it does and how to
//! record it.

use super::{matrix2, rand_tensor, Case, Work};
use crate::peaks;
use vkdiff_runtime::ops::{self, AttentionLayout, ConvParams, Matmul, MatrixCeiling, UnaryOp};
use vkdiff_runtime::{Context, DeviceKind, Dtype};

pub(super) fn gemm_case(
    ctx: &Context,
    dtype: Dtype,
    m: usize,
    n: usize,
    k: usize,
    linear: bool,
) -> vkdiff_runtime::Result<Case> {
    let b_shape = if linear { [n, k] } else { [k, n] };
    Ok(Case {
        name: if linear { "linear (B = weight, N×K)" } else { "gemm" },
        shape: format!("M={m} N={n} K={k}"),
        work: Work::Flops(2.0 * (m * n * k) as f64),
        gemm: Some((m, n, k)),
        on_gemm_family: true,
        tensors: vec![
            rand_tensor(ctx, &[m, k], dtype, 1)?,
            rand_tensor(ctx, &b_shape, dtype, 2)?,
            ctx.zeros(&[m, n], dtype)?,
        ],
        record: if linear {
            |rec, t| ops::linear(rec, &t[0], &t[1], None, &t[2])
        } else {
            |rec, t| {
                let (m, k, n) = (t[0].shape()[0], t[0].shape()[1], t[1].shape()[1]);
                ops::matmul(rec, &t[0], &t[1], None, &t[2], &Matmul::dense(m, n, k, false))
            }
        },
    })
}

/// SDXL's feed-forward projection at 64×64 (640 → 2×2560, bias) followed by GEGLU: fused into
/// the product's epilogue, or the projection stored and read back by the GEGLU kernel.
fn linear_geglu_case(ctx: &Context, dtype: Dtype, fused: bool) -> vkdiff_runtime::Result<Case> {
    let (m, n, k) = (64 * 64, 5120, 640);
    Ok(Case {
        name: if fused { "linear + GEGLU, fused" } else { "linear, then GEGLU" },
        shape: format!("M={m} N={n} K={k} -> {}", n / 2),
        work: Work::Flops(2.0 * (m * n * k) as f64),
        gemm: None,
        on_gemm_family: true,
        tensors: vec![
            rand_tensor(ctx, &[m, k], dtype, 21)?,
            rand_tensor(ctx, &[n, k], dtype, 22)?,
            rand_tensor(ctx, &[n], dtype, 23)?,
            ctx.zeros(&[m, n / 2], dtype)?,
            ctx.zeros(&[m, n], dtype)?,
        ],
        record: if fused {
            // The fused kernel itself, which `linear_geglu` leaves on quick-compile drivers.
            |rec, t| {
                let (m, k, n) = (t[0].shape()[0], t[0].shape()[1], t[1].shape()[0]);
                ops::matmul(rec, &t[0], &t[1], Some(&t[2]), &t[3], &Matmul::linear_geglu(m, n, k))
            }
        } else {
            |rec, t| {
                ops::linear(rec, &t[0], &t[1], Some(&t[2]), &t[4])?;
                ops::geglu(rec, &t[4], &t[3])
            }
        },
    })
}

/// The matrix units' ceiling on this device (kernels/wgsl/coop_ceiling.wgsl): sized to keep a
/// GPU busy for milliseconds, and a CPU device (lavapipe, emulating them) for far less.
fn ceiling_run(ctx: &Context, from_shared: bool) -> Option<MatrixCeiling> {
    let fragment = ctx.info().cooperative_variant()?;
    let (groups, reps) = if ctx.info().kind == DeviceKind::Cpu { (16, 64) } else { (2048, 4096) };
    Some(MatrixCeiling { fragment, groups, reps, step: 1, from_shared })
}

/// The ceiling's two rows, where the products run on the matrix units.
fn ceiling_cases(ctx: &Context) -> vkdiff_runtime::Result<Vec<Case>> {
    let mut cases = Vec::new();
    for from_shared in [false, true] {
        let Some(run) = ceiling_run(ctx, from_shared).filter(|_| peaks::has_matrix_units(ctx)) else {
            break;
        };
        cases.push(Case {
            name: "matrix-unit ceiling",
            shape: format!(
                "{}, {}",
                run.fragment.shape(),
                if from_shared { "from workgroup memory" } else { "operands in registers" }
            ),
            work: Work::Flops(run.flops()),
            gemm: None,
            on_gemm_family: false,
            tensors: vec![
                rand_tensor(ctx, &[run.operand_len()], Dtype::F16, 30)?,
                ctx.zeros(&[run.sums_len()], Dtype::F32)?,
            ],
            record: if from_shared {
                |rec, t| {
                    let run = ceiling_run(rec.context(), true).expect("a ceiling case exists");
                    ops::matrix_ceiling(rec, &t[0], &t[1], &run)
                }
            } else {
                |rec, t| {
                    let run = ceiling_run(rec.context(), false).expect("a ceiling case exists");
                    ops::matrix_ceiling(rec, &t[0], &t[1], &run)
                }
            },
        });
    }
    Ok(cases)
}

/// Self-attention over the 4096 tokens of a 64×64 level in `heads` heads of `d` values.
pub(super) fn self_attention_case(
    ctx: &Context,
    dtype: Dtype,
    heads: usize,
    d: usize,
    seed: u32,
) -> vkdiff_runtime::Result<Case> {
    Ok(Case {
        name: "attention",
        shape: format!("4096 tokens, {heads} head{} x {d}", if heads > 1 { "s" } else { "" }),
        work: Work::Flops(4.0 * 4096.0 * 4096.0 * (heads * d) as f64),
        gemm: None,
        on_gemm_family: false,
        tensors: (0..4)
            .map(|i| rand_tensor(ctx, &[1, 4096, heads, d], dtype, seed + i))
            .collect::<vkdiff_runtime::Result<_>>()?,
        record: |rec, t| {
            let [n, heads, d] = [t[0].shape()[1], t[0].shape()[2], t[0].shape()[3]];
            let l = AttentionLayout::dense(1, heads, d, n, n);
            ops::attention(rec, &t[0], &t[1], &t[2], &t[3], &l, (d as f32).sqrt().recip())
        },
    })
}

/// The 3×3 convolutions timed: (images, side, channels in and out) of the 64×64 level, then the
/// UNet's own at 1024² with guidance (two latents) at its 128×128, 64×64 and 32×32 levels.
pub(super) const CONV_ROWS: [(usize, usize, usize); 4] = [(1, 64, 640), (2, 128, 320), (2, 64, 640), (2, 32, 1280)];

/// "2 x 128x128, 320->320": a row of [`CONV_ROWS`], its images counted where there are several.
pub(super) fn conv_shape((images, side, c): (usize, usize, usize)) -> String {
    let batch = if images > 1 { format!("{images} x ") } else { String::new() };
    format!("{batch}{side}x{side}, {c}->{c}")
}

/// A 3×3 convolution of `images` × side² pixels, `c` channels in and out, stride 1.
pub(super) fn conv3x3_case(
    ctx: &Context,
    dtype: Dtype,
    (images, side, c): (usize, usize, usize),
) -> vkdiff_runtime::Result<Case> {
    let pixels = images * side * side;
    Ok(Case {
        name: "conv2d 3x3",
        shape: format!("{}, stride 1", conv_shape((images, side, c))),
        work: Work::Flops(2.0 * (pixels * c * 9 * c) as f64),
        gemm: None,
        on_gemm_family: true,
        tensors: vec![
            rand_tensor(ctx, &[images, side, side, c], dtype, 3)?,
            rand_tensor(ctx, &[c, 3, 3, c], dtype, 4)?,
            rand_tensor(ctx, &[c], dtype, 5)?,
            ctx.zeros(&[images, side, side, c], dtype)?,
        ],
        record: |rec, t| ops::conv2d(rec, &t[0], &t[1], Some(&t[2]), &t[3], &ConvParams::new(1, 1)),
    })
}

/// The linear rows: a 64×64 level's projection, then the UNet's own products at 1024² with
/// guidance (two latents): the 32×32 level's attention projections and feed-forward output, and
/// the 64×64 level's projections.
const LINEAR_ROWS: [(usize, usize, usize); 4] =
    [(4096, 640, 640), (2 * 1024, 1280, 1280), (2 * 1024, 1280, 5120), (2 * 4096, 640, 640)];

pub(super) fn cases(ctx: &Context, dtype: Dtype) -> vkdiff_runtime::Result<Vec<Case>> {
    let bytes = |n: usize| (n * vkdiff_runtime::dtype_size(dtype)) as f64;
    let (hw, c) = (64 * 64, 640);
    let mut cases =
        vec![gemm_case(ctx, dtype, 1024, 1024, 1024, false)?, gemm_case(ctx, dtype, 4096, 640, 640, false)?];
    for &(m, n, k) in &LINEAR_ROWS {
        cases.push(gemm_case(ctx, dtype, m, n, k, true)?);
    }
    for &row in &CONV_ROWS {
        cases.push(conv3x3_case(ctx, dtype, row)?);
    }
    cases.extend([
        self_attention_case(ctx, dtype, 10, 64, 6)?,
        // The VAE decoder's mid-block at 512² (a 64×64 latent): one head of all 512 channels.
        self_attention_case(ctx, dtype, 1, 512, 14)?,
        Case {
            name: "cross-attention",
            shape: "4096 x 77 tokens, 10 heads x 64".into(),
            work: Work::Flops(4.0 * 4096.0 * 77.0 * 64.0 * 10.0),
            gemm: None,
            on_gemm_family: false,
            tensors: vec![
                rand_tensor(ctx, &[1, 4096, 640], dtype, 10)?,
                rand_tensor(ctx, &[1, 77, 640], dtype, 11)?,
                rand_tensor(ctx, &[1, 77, 640], dtype, 12)?,
                ctx.zeros(&[1, 4096, 640], dtype)?,
            ],
            record: |rec, t| {
                let l = AttentionLayout::dense(1, 10, 64, 4096, 77);
                ops::attention(rec, &t[0], &t[1], &t[2], &t[3], &l, 0.125)
            },
        },
        Case {
            name: "group_norm + SiLU",
            shape: "64x64x640, 32 groups".into(),
            work: Work::Bytes(4.0 * bytes(hw * c)),
            gemm: None,
            on_gemm_family: false,
            tensors: vec![
                rand_tensor(ctx, &[1, hw, c], dtype, 13)?,
                rand_tensor(ctx, &[c], dtype, 14)?,
                rand_tensor(ctx, &[c], dtype, 15)?,
                ctx.zeros(&[1, hw, c], dtype)?,
            ],
            record: |rec, t| ops::group_norm(rec, &t[0], &t[1], &t[2], &t[3], 32, 1e-5, true),
        },
        Case {
            name: "group_norm + SiLU",
            shape: "128x128x320, 32 groups".into(),
            work: Work::Bytes(4.0 * bytes(4 * hw * c / 2)),
            gemm: None,
            on_gemm_family: false,
            tensors: vec![
                rand_tensor(ctx, &[1, 4 * hw, c / 2], dtype, 24)?,
                rand_tensor(ctx, &[c / 2], dtype, 25)?,
                rand_tensor(ctx, &[c / 2], dtype, 26)?,
                ctx.zeros(&[1, 4 * hw, c / 2], dtype)?,
            ],
            record: |rec, t| ops::group_norm(rec, &t[0], &t[1], &t[2], &t[3], 32, 1e-5, true),
        },
        Case {
            name: "layer_norm",
            shape: "4096 x 640".into(),
            work: Work::Bytes(4.0 * bytes(hw * c)),
            gemm: None,
            on_gemm_family: false,
            tensors: vec![
                rand_tensor(ctx, &[hw, c], dtype, 16)?,
                rand_tensor(ctx, &[c], dtype, 17)?,
                rand_tensor(ctx, &[c], dtype, 18)?,
                ctx.zeros(&[hw, c], dtype)?,
            ],
            record: |rec, t| ops::layer_norm(rec, &t[0], &t[1], &t[2], &t[3], 1e-5),
        },
        Case {
            name: "silu",
            shape: "64x64x640".into(),
            work: Work::Bytes(2.0 * bytes(hw * c)),
            gemm: None,
            on_gemm_family: false,
            tensors: vec![rand_tensor(ctx, &[hw * c], dtype, 19)?, ctx.zeros(&[hw * c], dtype)?],
            record: |rec, t| ops::unary(rec, UnaryOp::Silu, &t[0], &t[1], 1.0),
        },
        Case {
            name: "add (residual)",
            shape: "64x64x640".into(),
            work: Work::Bytes(3.0 * bytes(hw * c)),
            gemm: None,
            on_gemm_family: false,
            tensors: vec![
                rand_tensor(ctx, &[1, hw, c], dtype, 27)?,
                rand_tensor(ctx, &[1, hw, c], dtype, 28)?,
                ctx.zeros(&[1, hw, c], dtype)?,
            ],
            record: |rec, t| ops::add(rec, &t[0], &t[1], &t[2]),
        },
        Case {
            name: "geglu",
            shape: "4096 x 2x2560".into(),
            work: Work::Bytes(3.0 * bytes(hw * 2560)),
            gemm: None,
            on_gemm_family: false,
            tensors: vec![rand_tensor(ctx, &[hw, 5120], dtype, 20)?, ctx.zeros(&[hw, 2560], dtype)?],
            record: |rec, t| ops::geglu(rec, &t[0], &t[1]),
        },
        linear_geglu_case(ctx, dtype, true)?,
        linear_geglu_case(ctx, dtype, false)?,
    ]);
    if dtype == Dtype::F16 {
        cases.extend(ceiling_cases(ctx)?);
        cases.extend(matrix2::cases(ctx, &LINEAR_ROWS, &CONV_ROWS)?);
    }
    Ok(cases)
}
