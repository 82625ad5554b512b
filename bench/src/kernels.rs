//! `vkdiff bench kernels`: each kernel on SDXL-sized shapes, timed on the device.

use crate::cpu_reference::{self, CpuGemm};
use crate::peaks;
use anyhow::Result;
use std::time::{Duration, Instant};
use vkdiff_runtime::{eight_subgroups_built, Context, Dtype, GemmFamily, MatrixTile, Recorder, Tensor};

mod cases;
mod matrix2;

use cases::{cases, conv3x3_case, gemm_case, self_attention_case, CONV_ROWS};

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
        ("conv", conv3x3_case(ctx, dtype, CONV_ROWS[0])?),
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
