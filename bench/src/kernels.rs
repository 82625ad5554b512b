//! `vkdiff bench kernels`: each kernel on SDXL-sized shapes, timed on the device.

use crate::cpu_reference::{self, CpuGemm};
use crate::peaks;
use anyhow::Result;
use std::time::{Duration, Instant};
use vkdiff_runtime::{Context, Dtype, Environment, GemmFamily, MatrixTile, Recorder, Tensor};

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

/// M, N and K of a product held against the CPU's.
type GemmShape = (usize, usize, usize);

struct Case {
    name: &'static str,
    shape: String,
    work: Work,
    /// The GEMM shape to hold against the CPU, if any.
    gemm: Option<GemmShape>,
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
        "{:<26} {:<5} {:<32} {:<32} {:>10.3} {:>9} {:>8} {:>10}",
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

pub fn run(args: &KernelsArgs, env: &Environment) -> Result<()> {
    let ctx = args.common.device.open(env)?;
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
            ctx.choices().gemm_family
        );
        if let Some(trial) = peaks::trial_label(&ctx) {
            println!("matrix-unit trial: {trial}");
        }
        println!(
            "{:<26} {:<5} {:<32} {:<32} {:>10} {:>9} {:>8} {:>10}",
            "kernel", "dtype", "GEMM kernels", "shape", "ms", "GFLOP/s", "GB/s", "of matrix peak"
        );
    }
    let mut failed = Vec::new();
    for dtype in dtypes {
        let cases = cases(&ctx, dtype)?.into_iter();
        let chosen = cases.filter(|c| args.filter.as_ref().is_none_or(|f| c.name.contains(f.as_str())));
        let timed = time_cases(&ctx, dtype, chosen, args.samples, !args.common.json);
        gemm_shapes.extend(timed.rows.iter().filter_map(|(_, g)| *g));
        rows.extend(timed.rows);
        failed.extend(timed.failed);
    }
    gemm_shapes.dedup();
    let cpu: Result<Vec<CpuGemm>, String> = if args.common.no_cpu_reference || gemm_shapes.is_empty() {
        Ok(vec![])
    } else {
        cpu_reference::measure(env, &gemm_shapes)
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
            "gemm_family": format!("{:?}", ctx.choices().gemm_family),
            "matrix_unit_trial": ctx.matrix_unit_trial().map(|t| serde_json::json!({
                "cooperative_ms": t.cooperative_ms, "tiled_ms": t.tiled_ms, "difference": t.difference,
                "kept": t.keeps_matrix_units(),
            })),
            "kernels": rows.iter().map(|(r, _)| r).collect::<Vec<_>>(),
            "failed": failed,
            "cpu_reference": cpu
                .as_ref()
                .map(|c| serde_json::to_value(c).unwrap())
                .unwrap_or_else(|e| serde_json::Value::String(e.clone())),
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return rows_failed(&failed);
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
    rows_failed(&failed)
}

/// The error that ends a run in which rows failed, once every other row is printed.
fn rows_failed(failed: &[String]) -> Result<()> {
    match failed {
        [] => Ok(()),
        _ => anyhow::bail!("{} of the rows failed: {}", failed.len(), failed.join("; ")),
    }
}

/// What `time_cases` measured: each row with the GEMM shape to hold against the CPU, and a line
/// for each row that failed.
struct Timed {
    rows: Vec<(Row, Option<GemmShape>)>,
    failed: Vec<String>,
}

/// Times each case, products on each family the device has (the matrix units in each workgroup
/// tile built for the device's fragment, so one run compares them), printing each row as it comes where
/// `print`. A row that fails (a driver that refuses a kernel no GPU has run) is one line naming
/// it, and the rest still run; the context's family and tile are left as found.
fn time_cases(ctx: &Context, dtype: Dtype, cases: impl Iterator<Item = Case>, samples: usize, print: bool) -> Timed {
    let default_family = ctx.choices().gemm_family;
    let default_tile = ctx.choices().matrix_tile;
    let mut timed = Timed { rows: Vec::new(), failed: Vec::new() };
    for case in cases {
        let four = MatrixTile::Four;
        let families = match (case.on_gemm_family, default_family) {
            (false, _) => vec![(None, default_tile)],
            (true, GemmFamily::Cooperative | GemmFamily::Tiled)
                if dtype == Dtype::F16 && peaks::has_matrix_units(ctx) =>
            {
                let units = Some(GemmFamily::Cooperative);
                let fragment = ctx.info().cooperative_variant();
                let built = |tile: &MatrixTile| fragment.is_some_and(|f| tile.built_for(&f));
                let mut runs = vec![(units, four)];
                runs.extend(MatrixTile::EIGHT_SUBGROUPS.iter().filter(|t| built(t)).map(|&t| (units, t)));
                runs.push((Some(GemmFamily::Tiled), four));
                runs
            }
            (true, family) => vec![(Some(family), default_tile)],
        };
        for (family, tile) in families {
            ctx.choose(|c| c.gemm_family = family.unwrap_or(default_family));
            ctx.choose(|c| c.matrix_tile = tile);
            match time_row(ctx, &case, dtype, family.is_some(), samples) {
                Ok(row) => {
                    if print {
                        print_row(&row);
                    }
                    timed.rows.push((row, case.gemm));
                }
                Err(e) => {
                    let what = format!("{} {} ({})", case.name, case.shape, dtype_name(dtype));
                    if print {
                        println!("{what:<60} failed: {e:#}");
                    }
                    timed.failed.push(format!("{what}: {e:#}"));
                }
            }
        }
        ctx.choose(|c| c.gemm_family = default_family);
        ctx.choose(|c| c.matrix_tile = default_tile);
    }
    timed
}

#[cfg(test)]
mod tests {
    use super::*;
    use vkdiff_runtime::ops::{unary, UnaryOp};

    fn silu(ctx: &Context, record: fn(&mut Recorder, &[Tensor]) -> vkdiff_runtime::Result<()>) -> Case {
        Case {
            name: "silu",
            shape: "4096".into(),
            work: Work::Bytes(2.0 * 4096.0 * 4.0),
            gemm: None,
            on_gemm_family: false,
            tensors: vec![rand_tensor(ctx, &[4096], Dtype::F32, 1).unwrap(), ctx.zeros(&[4096], Dtype::F32).unwrap()],
            record,
        }
    }

    #[test]
    fn a_failing_row_is_named_and_the_rest_still_run() {
        let ctx = vkdiff_testkit::ctx();
        let refused: fn(&mut Recorder, &[Tensor]) -> vkdiff_runtime::Result<()> =
            |_, _| Err(vkdiff_runtime::Error::Shape("planted: the driver refused the kernel".into()));
        let works: fn(&mut Recorder, &[Tensor]) -> vkdiff_runtime::Result<()> =
            |rec, t| unary(rec, UnaryOp::Silu, &t[0], &t[1], 1.0);
        let cases = [silu(&ctx, refused), silu(&ctx, works)];
        let timed = time_cases(&ctx, Dtype::F32, cases.into_iter(), 1, false);
        assert_eq!(timed.failed, ["silu 4096 (f32): planted: the driver refused the kernel"]);
        assert_eq!(timed.rows.len(), 1, "the row after the failure still runs");
        assert!(timed.rows[0].0.gbps.is_some_and(|g| g > 0.0));
        let err = rows_failed(&timed.failed).unwrap_err().to_string();
        assert_eq!(err, "1 of the rows failed: silu 4096 (f32): planted: the driver refused the kernel");
        assert!(rows_failed(&[]).is_ok());
    }
}
