//! `vkdiff bench fid`: images per second of FID features (torch-fidelity's InceptionV3, the real
//! architecture with random weights) over a folder of PNGs, decoding included, on the device,
//! beside torch-fidelity on this machine's CPU over the same folder in the same run.

use anyhow::{Context as _, Result};
use std::path::{Path, PathBuf};
use std::time::Instant;
use vkdiff_args::Precision;
use vkdiff_eval::fid::FeatureExtractor;
use vkdiff_formats::write_safetensors_f32;
use vkdiff_networks::RandomInception;
use vkdiff_pipeline::RgbImage;
use vkdiff_runtime::Environment;

const REFERENCE: crate::cpu_reference::Script = crate::cpu_reference::script!("fid_cpu_reference.py");

#[derive(clap::Args)]
pub struct FidArgs {
    #[command(flatten)]
    common: crate::common::Common,
    /// Images in the folder.
    #[arg(long, default_value_t = 32)]
    images: usize,
    /// Their side in pixels (the paper's crops are 1024; all are resized to 299).
    #[arg(long, default_value_t = 512)]
    size: usize,
    /// Images per batch, on both sides.
    #[arg(long, default_value_t = 8)]
    batch: usize,
    /// f32 (torch-fidelity's) or f16.
    #[arg(long, value_enum, default_value_t = Precision::F32)]
    precision: Precision,
}

#[derive(serde::Serialize)]
struct Row {
    device: String,
    images: usize,
    size: usize,
    batch: usize,
    precision: String,
    load_s: f64,
    images_per_s: f64,
    peak_mib: f64,
    cpu_reference_images_per_s: Option<f64>,
    cpu_reference: String,
    ratio_to_cpu: Option<f64>,
}

pub fn run(args: &FidArgs, env: &Environment) -> Result<()> {
    vkdiff_args::ensure_usage(args.images > 0 && args.size > 0 && args.batch > 0, || {
        "--images, --size and --batch must be positive".into()
    })?;
    let dir = std::env::temp_dir().join(format!("vkdiff-bench-fid-{}", std::process::id()));
    let result = bench(args, env, &dir);
    let _ = std::fs::remove_dir_all(&dir);
    let row = result?;
    args.common.print(&row, |row| {
        let reference = row
            .cpu_reference_images_per_s
            .map_or(row.cpu_reference.clone(), |r| format!("{r:.2} images/s ({})", row.cpu_reference));
        format!(
            "{} | FID features, {} PNGs of {}², batch {} {}: {:.2} images/s (load {:.1} s, peak {:.0} MiB) | \
            torch-fidelity CPU f32: {reference} | speed-up {}",
            row.device,
            row.images,
            row.size,
            row.batch,
            row.precision,
            row.images_per_s,
            row.load_s,
            row.peak_mib,
            row.ratio_to_cpu.map_or("-".into(), |r| format!("{r:.2}×")),
        )
    })
}

fn bench(args: &FidArgs, env: &Environment, dir: &Path) -> Result<Row> {
    let files = write_images(dir, args.images, args.size)?;
    let weights = dir.join("inception-random.safetensors");
    write_safetensors_f32(&weights, &RandomInception::new().tensors(), &Default::default())?;
    let mut row = {
        let ctx = args.common.device.open(env)?;
        let start = Instant::now();
        let extractor = FeatureExtractor::new(&ctx, &weights, args.precision.dtype(), args.batch)?;
        let load_s = start.elapsed().as_secs_f64();
        // One batch first, so pipeline creation and the driver's compilation are not timed.
        extractor.features(&files[..args.batch.min(files.len())], None, &mut |_, _| {})?;
        let start = Instant::now();
        extractor.features(&files, None, &mut |_, _| {})?;
        let seconds = start.elapsed().as_secs_f64();
        Row {
            device: ctx.info().name.clone(),
            images: files.len(),
            size: args.size,
            batch: args.batch,
            precision: format!("{:?}", args.precision).to_lowercase(),
            load_s,
            images_per_s: files.len() as f64 / seconds,
            peak_mib: ctx.peak_bytes() as f64 / (1 << 20) as f64,
            cpu_reference_images_per_s: None,
            cpu_reference: String::new(),
            ratio_to_cpu: None,
        }
    };
    if args.common.no_cpu_reference {
        row.cpu_reference = "not run (--no-cpu-reference)".into();
    } else {
        match reference(env, &weights, dir, args.batch) {
            Ok((rate, what)) => {
                (row.cpu_reference_images_per_s, row.cpu_reference, row.ratio_to_cpu) =
                    (Some(rate), what, Some(row.images_per_s / rate))
            }
            Err(why) => row.cpu_reference = format!("unavailable: {why}"),
        }
    }
    Ok(row)
}

/// Smooth colour fields with noise, as PNGs named in order.
fn write_images(dir: &Path, n: usize, size: usize) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let mut state = 0x2545_f491_4f6c_dd1du64;
    (0..n)
        .map(|i| {
            let pixels = (0..size * size * 3)
                .map(|j| {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    let (y, x, c) = (j / (3 * size), j / 3 % size, j % 3);
                    let wave =
                        ((y as f32 * 0.02 * (c + 1) as f32 + i as f32).sin() * (x as f32 * 0.015).cos() * 90.0) + 127.0;
                    (wave + (state >> 59) as f32).clamp(0.0, 255.0) as u8
                })
                .collect();
            let path = dir.join(format!("{i:05}.png"));
            let bytes = vkdiff_pipeline::files::png_bytes(
                &RgbImage { width: size, height: size, pixels },
                &Default::default(),
            )?;
            std::fs::write(&path, bytes)?;
            Ok(path)
        })
        .collect()
}

/// torch-fidelity on the CPU: images per second and what ran it.
fn reference(
    env: &Environment,
    weights: &Path,
    dir: &Path,
    batch: usize,
) -> std::result::Result<(f64, String), String> {
    let out: FeatureRate = crate::cpu_reference::run_python_reference(
        env,
        REFERENCE,
        [weights.as_os_str(), dir.as_os_str(), batch.to_string().as_ref()],
        None,
    )?;
    let what = format!("torch {} / torch-fidelity {}, {} threads", out.torch, out.torch_fidelity, out.threads);
    Ok((out.images_per_s, what))
}

/// What `tools/fid_cpu_reference.py` prints (and more, unread).
#[derive(serde::Deserialize)]
struct FeatureRate {
    images_per_s: f64,
    torch: String,
    torch_fidelity: String,
    threads: usize,
}
