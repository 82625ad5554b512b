//! The peer on the same Vulkan device: stable-diffusion.cpp's Vulkan build (ggml-vulkan, as the
//! `cyllama-vulkan` wheel carries it) and vkdiff timing SDXL text-to-image from one file, SDXL's
//! architecture with the benchmarks' random weights written in the original single-file layout
//! (the only one sd.cpp reads for SDXL). vkdiff's steps are timed here; sd.cpp's run after the
//! device is released (tools/sdcpp_reference.py), bounded, since its loader was seen stopping at
//! its second tensor on lavapipe: a run that does not finish says so instead of a number.

use super::figure::{Figure, Reference};
use super::networks::Job;
use super::Plan;
use crate::cpu_reference::{script, Script};
use crate::step_rate::steps_after_first;
use anyhow::Result;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use vkdiff_networks::{write_random_single_file, SdxlConfigs};
use vkdiff_pipeline::{Guides, Sdxl};
use vkdiff_runtime::{Context, Environment};

const SDCPP_REFERENCE: Script = script!("sdcpp_reference.py");

/// What `tools/sdcpp_reference.py` prints: the load, each sampling step as sd.cpp's progress
/// line gives it, and what ran.
#[derive(serde::Deserialize)]
struct SdcppTimes {
    load_s: f64,
    steps: Vec<f64>,
    what: String,
}

/// The file both read; `written` is this run's folder that holds it, which the peer's job removes.
pub struct PeerFile {
    pub written: Option<PathBuf>,
    pub model: PathBuf,
}

/// Times vkdiff's text-to-image from one file (the user's `--model`, else SDXL's random weights
/// written for the purpose) and returns the figure with the job that times sd.cpp on it.
pub fn peer(ctx: &Context, plan: &Plan, user: Option<&Path>) -> Result<(Figure, Job)> {
    let dir = std::env::temp_dir().join(format!("vkdiff-report-peer-{}", std::process::id()));
    let made = write_and_time(ctx, plan, user, &dir);
    if made.is_err() {
        let _ = std::fs::remove_dir_all(&dir);
    }
    made
}

fn write_and_time(ctx: &Context, plan: &Plan, user: Option<&Path>, dir: &Path) -> Result<(Figure, Job)> {
    let (file, note) = match user {
        Some(model) => (PeerFile { written: None, model: model.to_path_buf() }, None),
        None => {
            std::fs::create_dir_all(dir)?;
            let model = dir.join("sdxl-random.safetensors");
            eprintln!("report: SDXL's random weights in the original single-file layout, for stable-diffusion.cpp");
            let start = Instant::now();
            let bytes = write_random_single_file(ctx, &SdxlConfigs::sdxl_base(), &model)?;
            let note = format!(
                "{:.1} GB of random f16 weights written in {:.0} s, read by both",
                bytes as f64 / 1e9,
                start.elapsed().as_secs_f64()
            );
            (PeerFile { written: Some(dir.to_path_buf()), model }, Some(note))
        }
    };
    let model = file.model.clone();
    let (size, steps) = (plan.image_size, plan.steps_timed);
    eprintln!("report: SDXL text-to-image {size}², {steps} steps, from that file");
    let start = Instant::now();
    let sdxl = Sdxl::load(ctx, &model, plan.dtype, &mut |_| {})?;
    let load_s = start.elapsed().as_secs_f64();
    ctx.reset_peak();
    let job = crate::gen::bench_job(size, steps);
    let out = sdxl.text_to_image(&job, &Guides::default(), &mut |_, _| {})?;
    let t = &out.timings;
    let step_s: Vec<f64> = t.steps.iter().map(|d| d.as_secs_f64()).collect();
    let figure = Figure {
        id: "peer.sdcpp".into(),
        group: "peer".into(),
        label: format!("SDXL text-to-image {size}², a step (batch 2, guidance 5), from one single file"),
        unit: "s".into(),
        higher_is_better: false,
        runs: steps_after_first(&step_s).map_err(anyhow::Error::msg)?,
        first_run: step_s.first().copied(),
        peak_mib: Some(ctx.peak_bytes() as f64 / (1 << 20) as f64),
        parts: vec![
            ("load".into(), load_s),
            ("text encoders".into(), t.text_encoding.as_secs_f64()),
            ("VAE".into(), t.vae.as_secs_f64()),
        ],
        note,
        peak_share: None,
        reference: Reference::Missing { why: String::new() },
    };
    let job = if model.is_file() {
        Job::Peer { file, size, steps }
    } else {
        Job::None("stable-diffusion.cpp reads SDXL as one single file only; --model is a folder".into())
    };
    Ok((figure, job))
}

/// sd.cpp's step on the same file and device (the median of its steps after the first, as
/// vkdiff's), or why there is none; the file goes.
pub fn sdcpp(env: &Environment, file: &PeerFile, size: usize, steps: usize, timeout: Duration) -> Reference {
    eprintln!("report: stable-diffusion.cpp's text-to-image from the same file (at most {} s)", timeout.as_secs());
    let args = [file.model.display().to_string(), size.to_string(), steps.to_string()];
    let run = crate::cpu_reference::run_python_reference_within(env, SDCPP_REFERENCE, args, None, Some(timeout));
    if let Some(dir) = &file.written {
        let _ = std::fs::remove_dir_all(dir);
    }
    let rate = run.and_then(|out: SdcppTimes| {
        let step = steps_after_first(&out.steps).map_err(|why| format!("{}: {why}", SDCPP_REFERENCE.path))?;
        Ok(Reference::Measured { value: step.median, what: format!("{}, loaded in {:.0} s", out.what, out.load_s) })
    });
    rate.unwrap_or_else(|why| Reference::Missing { why: format!("stable-diffusion.cpp (cyllama-vulkan): {why}") })
}
