//! `vkdiff bench kernels`: each kernel on SDXL-sized shapes, timed on the device.

use crate::cpu_reference::{self, CpuGemm};
use crate::peaks;
use anyhow::Result;
use std::time::{Duration, Instant};
use vkdiff_runtime::ops::{self, AttentionLayout, ConvParams, Matmul, MatrixCeiling, UnaryOp};
use vkdiff_runtime::{eight_subgroups_built, Context, DeviceKind, Dtype, GemmFamily, MatrixTile, Recorder, Tensor};

mod matrix2;

#[derive(clap::Args)]
pub struct KernelsArgs {
    #[command(flatten)]
    common: crate::common::Common,
    /// Only run kernels whose name contains this.
    #[arg(long)]
    filter: Option<String>,
    /// Timed samples per kernel; the best is reported.
    #[arg(long, default_value_t = 3)]
    samples: usize,
}

/// What one run of a case does, for the throughput figure.
#[derive(Clone, Copy)]
enum Work {
    Flops(f64),
    Bytes(f64),
}

struct Case {
    name: &'static str,
    shape: String,
    work: Work,
    /// The GEMM shape to hold against the CPU, if any.
    gemm: Option<(usize, usize, usize)>,
    /// Whether it runs on the GEMM/convolution family (timed on each family the device has).
    on_gemm_family: bool,
    tensors: Vec<Tensor>,
    record: fn(&mut Recorder, &[Tensor]) -> vkdiff_runtime::Result<()>,
}

#[derive(serde::Serialize)]
struct Row {
    kernel: &'static str,
    dtype: String,
    /// The GEMM/convolution kernels it ran on, for products.
    family: Option<String>,
    shape: String,
    ms: f64,
    gflops: Option<f64>,
    gbps: Option<f64>,
    /// GFLOP/s as a share of the GPU's f16 matrix-unit peak ("unknown" off the table).
    matrix_peak_share: Option<String>,
    cpu_gflops: Option<f64>,
    ratio_to_cpu: Option<f64>,
}

pub(super) fn dtype_name(d: Dtype) -> &'static str {
    match d {
        Dtype::F32 => "f32",
        Dtype::F16 => "f16",
    }
}

pub(super) fn rand_tensor(ctx: &Context, shape: &[usize], dtype: Dtype, seed: u32) -> vkdiff_runtime::Result<Tensor> {
    let n: usize = shape.iter().product();
    let data: Vec<f32> = (0..n)
        .map(|i| (((i as u32).wrapping_mul(2654435761).wrapping_add(seed) >> 8) as f32 / (1u32 << 24) as f32) - 0.5)
        .collect();
    ctx.upload(shape, dtype, &data)
}

fn gemm_case(ctx: &Context, dtype: Dtype, m: usize, n: usize, k: usize, linear: bool) -> vkdiff_runtime::Result<Case> {
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
fn self_attention_case(ctx: &Context, dtype: Dtype, heads: usize, d: usize, seed: u32) -> vkdiff_runtime::Result<Case> {
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

/// The 64×64 level's 3×3 convolution, 640 channels in and out.
fn conv3x3_case(ctx: &Context, dtype: Dtype) -> vkdiff_runtime::Result<Case> {
    let (hw, c) = (64 * 64, 640);
    Ok(Case {
        name: "conv2d 3x3",
        shape: "64x64, 640->640, stride 1".into(),
        work: Work::Flops(2.0 * (hw * c * 9 * c) as f64),
        gemm: None,
        on_gemm_family: true,
        tensors: vec![
            rand_tensor(ctx, &[1, 64, 64, c], dtype, 3)?,
            rand_tensor(ctx, &[c, 3, 3, c], dtype, 4)?,
            rand_tensor(ctx, &[c], dtype, 5)?,
            ctx.zeros(&[1, 64, 64, c], dtype)?,
        ],
        record: |rec, t| ops::conv2d(rec, &t[0], &t[1], Some(&t[2]), &t[3], &ConvParams::new(1, 1)),
    })
}

/// A headline product of `bench report`, timed.
pub(crate) struct HeadlineRuns {
    pub id: &'static str,
    pub label: String,
    /// The first run, one repetition (kernels compiled on first dispatch).
    pub first_s: f64,
    /// TFLOP/s of each timed run.
    pub tflops: Vec<f64>,
}

/// SDXL's headline products at 1024²: the 32×32 level's feed-forward output (a 2048×1280×5120
/// linear), the 64×64 level's 3×3 convolution and its self-attention over 4096 tokens.
pub(crate) fn headline(ctx: &Context, dtype: Dtype, runs: usize) -> Result<Vec<HeadlineRuns>> {
    let cases = [
        ("linear", gemm_case(ctx, dtype, 2 * 1024, 1280, 5120, true)?),
        ("conv", conv3x3_case(ctx, dtype)?),
        ("attention", self_attention_case(ctx, dtype, 10, 64, 6)?),
    ];
    let mut out = Vec::new();
    for (id, case) in cases {
        let Work::Flops(flops) = case.work else { unreachable!("products count FLOPs") };
        let (first, timed) = time_case_runs(ctx, &case, runs)?;
        out.push(HeadlineRuns {
            id,
            label: format!("{} {}, {}", case.name, case.shape, dtype_name(dtype)),
            first_s: first.as_secs_f64(),
            tflops: timed.iter().map(|t| flops / t.as_secs_f64() / 1e12).collect(),
        });
    }
    Ok(out)
}

/// The linear rows: a 64×64 level's projection, then the UNet's own products at 1024² with
/// guidance (two latents): the 32×32 level's attention projections and feed-forward output, and
/// the 64×64 level's projections.
const LINEAR_ROWS: [(usize, usize, usize); 4] =
    [(4096, 640, 640), (2 * 1024, 1280, 1280), (2 * 1024, 1280, 5120), (2 * 4096, 640, 640)];

fn cases(ctx: &Context, dtype: Dtype) -> vkdiff_runtime::Result<Vec<Case>> {
    let bytes = |n: usize| (n * vkdiff_runtime::dtype_size(dtype)) as f64;
    let (hw, c) = (64 * 64, 640);
    let mut cases =
        vec![gemm_case(ctx, dtype, 1024, 1024, 1024, false)?, gemm_case(ctx, dtype, 4096, 640, 640, false)?];
    for &(m, n, k) in &LINEAR_ROWS {
        cases.push(gemm_case(ctx, dtype, m, n, k, true)?);
    }
    cases.extend([
        conv3x3_case(ctx, dtype)?,
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
        cases.extend(matrix2::cases(ctx, &LINEAR_ROWS)?);
    }
    Ok(cases)
}

/// Best time of one case per repetition (see `time_case_runs`).
fn time_case(ctx: &Context, case: &Case, samples: usize) -> Result<Duration> {
    Ok(time_case_runs(ctx, case, samples)?.1.into_iter().min().expect("at least one sample"))
}

/// The first run of one case (the driver JITs on first dispatch), then `samples` runs of a
/// recording that repeats the case enough to last about half a second: each per repetition.
fn time_case_runs(ctx: &Context, case: &Case, samples: usize) -> Result<(Duration, Vec<Duration>)> {
    let record = |reps: usize| -> Result<vkdiff_runtime::Recording> {
        let mut rec = Recorder::new(ctx, false)?;
        for _ in 0..reps {
            (case.record)(&mut rec, &case.tensors)?;
        }
        Ok(rec.finish()?)
    };
    let timed = |recording: &vkdiff_runtime::Recording| -> Result<Duration> {
        let t = Instant::now();
        recording.run()?;
        Ok(t.elapsed())
    };
    let once = record(1)?;
    let first = timed(&once)?;
    let warm = timed(&once)?;
    let reps = (0.5 / warm.as_secs_f64().max(1e-6)).clamp(1.0, 200.0) as usize;
    let recording = if reps > 1 { record(reps)? } else { once };
    if reps > 1 {
        recording.run()?;
    }
    let runs = (0..samples.max(1)).map(|_| Ok(timed(&recording)? / reps as u32)).collect::<Result<_>>()?;
    Ok((first, runs))
}

/// One case timed on the context's current family.
fn time_row(ctx: &Context, case: &Case, dtype: Dtype, product: bool, samples: usize) -> Result<Row> {
    let t = time_case(ctx, case, samples)?.as_secs_f64();
    let (gflops, gbps) = match case.work {
        Work::Flops(f) => (Some(f / t / 1e9), None),
        Work::Bytes(b) => (None, Some(b / t / 1e9)),
    };
    Ok(Row {
        kernel: case.name,
        dtype: dtype_name(dtype).into(),
        family: product.then(|| peaks::family_label(ctx, dtype)),
        shape: case.shape.clone(),
        ms: t * 1e3,
        gflops,
        gbps,
        matrix_peak_share: gflops.map(|g| peaks::share_label(ctx, g * 1e9)),
        cpu_gflops: None,
        ratio_to_cpu: None,
    })
}

fn print_row(row: &Row) {
    let show = |x: Option<f64>| x.map_or(String::from("-"), |v| format!("{v:.1}"));
    println!(
        "{:<26} {:<5} {:<28} {:<32} {:>10.3} {:>9} {:>8} {:>10}",
        row.kernel,
        row.dtype,
        row.family.as_deref().unwrap_or("-"),
        row.shape,
        row.ms,
        show(row.gflops),
        show(row.gbps),
        row.matrix_peak_share.as_deref().unwrap_or("-"),
    );
}

pub fn run(args: &KernelsArgs) -> Result<()> {
    let ctx = Context::new(&args.common.device.choice())?;
    let info = ctx.info().clone();
    let dtypes: Vec<Dtype> = if info.supports_f16() { vec![Dtype::F32, Dtype::F16] } else { vec![Dtype::F32] };
    let mut rows = Vec::new();
    let mut gemm_shapes = Vec::new();
    if !args.common.json {
        println!(
            "device: {} ({}, {}), GEMM kernels: {:?}",
            info.name,
            info.kind.label(),
            info.driver,
            ctx.gemm_family()
        );
        if let Some(trial) = peaks::trial_label(&ctx) {
            println!("matrix-unit trial: {trial}");
        }
        println!(
            "{:<26} {:<5} {:<28} {:<32} {:>10} {:>9} {:>8} {:>10}",
            "kernel", "dtype", "GEMM kernels", "shape", "ms", "GFLOP/s", "GB/s", "of matrix peak"
        );
    }
    let default_family = ctx.gemm_family();
    let default_tile = ctx.matrix_tile();
    for dtype in dtypes {
        for case in cases(&ctx, dtype)? {
            if args.filter.as_ref().is_some_and(|f| !case.name.contains(f.as_str())) {
                continue;
            }
            // Products run on each family the device has, the matrix units in both workgroup
            // tiles where both are built, so one run compares them.
            let four = MatrixTile::Four;
            let families = match (case.on_gemm_family, default_family) {
                (false, _) => vec![(None, default_tile)],
                (true, GemmFamily::Cooperative | GemmFamily::Tiled)
                    if dtype == Dtype::F16 && peaks::has_matrix_units(&ctx) =>
                {
                    let units = Some(GemmFamily::Cooperative);
                    let eight = ctx.info().cooperative_variant().is_some_and(|f| eight_subgroups_built(&f));
                    let mut runs = vec![(units, four)];
                    runs.extend(eight.then_some((units, MatrixTile::Eight)));
                    runs.push((Some(GemmFamily::Tiled), four));
                    runs
                }
                (true, family) => vec![(Some(family), default_tile)],
            };
            for (family, tile) in families {
                ctx.set_gemm_family(family.unwrap_or(default_family));
                ctx.set_matrix_tile(tile);
                let row = time_row(&ctx, &case, dtype, family.is_some(), args.samples)?;
                if !args.common.json {
                    print_row(&row);
                }
                if let Some(g) = case.gemm {
                    gemm_shapes.push(g);
                }
                rows.push((row, case.gemm));
            }
            ctx.set_gemm_family(default_family);
            ctx.set_matrix_tile(default_tile);
        }
    }
    gemm_shapes.dedup();
    let cpu: Result<Vec<CpuGemm>, String> = if args.common.no_cpu_reference || gemm_shapes.is_empty() {
        Ok(vec![])
    } else {
        cpu_reference::measure(&gemm_shapes)
    };
    if let Ok(cpu) = &cpu {
        for (row, gemm) in &mut rows {
            if let Some(c) = cpu.iter().find(|c| Some((c.m, c.n, c.k)) == *gemm) {
                row.cpu_gflops = Some(c.gflops);
                row.ratio_to_cpu = row.gflops.map(|g| g / c.gflops);
            }
        }
    }
    if args.common.json {
        let out = serde_json::json!({
            "device": info.name, "driver": info.driver, "kind": info.kind.label(),
            "gemm_family": format!("{:?}", ctx.gemm_family()),
            "matrix_unit_trial": ctx.matrix_unit_trial().map(|t| serde_json::json!({
                "cooperative_ms": t.cooperative_ms, "tiled_ms": t.tiled_ms, "difference": t.difference,
                "kept": t.keeps_matrix_units(),
            })),
            "kernels": rows.iter().map(|(r, _)| r).collect::<Vec<_>>(),
            "cpu_reference": cpu
                .as_ref()
                .map(|c| serde_json::to_value(c).unwrap())
                .unwrap_or_else(|e| serde_json::Value::String(e.clone())),
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    match cpu {
        Ok(cpu) if !cpu.is_empty() => {
            println!(
                "\nagainst the CPU's float32 GEMM ({}, kernel {}), measured just now on this machine:",
                cpu[0].library, cpu[0].kernel
            );
            for (row, _) in rows.iter().filter(|(r, _)| r.ratio_to_cpu.is_some()) {
                println!(
                    "  {:<26} {:<5} {:<18} {:>7.1} GFLOP/s vs {:>7.1} = {:.2}x",
                    row.kernel,
                    row.dtype,
                    row.shape,
                    row.gflops.unwrap(),
                    row.cpu_gflops.unwrap(),
                    row.ratio_to_cpu.unwrap()
                );
            }
        }
        Ok(_) => {}
        Err(e) => println!("\nCPU reference not measured: {e} (needs numpy in $VKDIFF_REFERENCE_PYTHON, else python3)"),
    }
    Ok(())
}
