//! `vkdiff bench gen`: a whole text-to-image run with SDXL base's architecture and random
//! weights (text encoders, UNet, VAE), timed by stage on the device, beside diffusers'
//! StableDiffusionXLPipeline on this machine's CPU in the same run.

use crate::step_rate::steps_after_first;
use anyhow::Result;
use std::time::Instant;
use vkdiff_networks::{SDXL_BASE_CONFIG, SDXL_BIGG_CONFIG, SDXL_CLIP_L_CONFIG, SDXL_VAE_CONFIG};
use vkdiff_pipeline::{ClipTokenizer, Guides, SamplerKind, Sampling, Sdxl, TextToImage};
use vkdiff_runtime::{Dtype, Environment};

const REFERENCE: crate::cpu_reference::Script = crate::cpu_reference::script!("gen_cpu_reference.py");

#[derive(clap::Args)]
pub struct GenArgs {
    #[command(flatten)]
    common: crate::common::Common,
    /// Image sizes in pixels (square).
    #[arg(long, value_delimiter = ',', default_values_t = [512, 1024])]
    size: Vec<usize>,
    /// Denoising steps: at least 2, as a step's time is the median of those after the first.
    #[arg(long, default_value_t = 4, value_parser = at_least_two_steps)]
    steps: usize,
    /// f16 (f32 arithmetic, matrix units where the GPU has them) or f32.
    #[arg(long, value_enum, default_value_t = vkdiff_args::Precision::F16)]
    precision: vkdiff_args::Precision,
}

fn at_least_two_steps(text: &str) -> std::result::Result<usize, String> {
    match text.parse::<usize>() {
        Ok(steps) if steps >= 2 => Ok(steps),
        _ => Err("at least 2: a step's time is the median of the timed steps after the first".into()),
    }
}

#[derive(serde::Serialize, Default)]
struct Row {
    device: String,
    size: usize,
    steps: usize,
    precision: String,
    load_s: f64,
    text_s: f64,
    record_s: f64,
    step_s: f64,
    vae_s: f64,
    total_s: f64,
    peak_mib: f64,
    cpu_reference: Option<serde_json::Value>,
    step_ratio_to_cpu: Option<f64>,
}

pub fn run(args: &GenArgs, env: &Environment) -> Result<()> {
    let dtype = args.precision.dtype();
    for &size in &args.size {
        let mut row = measure(args, env, dtype, size)?;
        if !args.common.no_cpu_reference {
            let r = reference(env, size, args.steps);
            row.step_ratio_to_cpu = r.as_ref().ok().map(|(cpu, _)| cpu / row.step_s);
            row.cpu_reference = Some(r.map_or_else(|why| serde_json::json!({ "unavailable": why }), |(_, v)| v));
        }
        args.common.print(&row, |row| {
            format!(
                "{} | SDXL gen {size}² {} steps {}: text {:.2} s, {:.1} s/step, VAE {:.1} s, total {:.1} s (load \
                    {:.1} s, record {:.1} s), peak {:.0} MiB | diffusers CPU f32: {} | step speed-up {}",
                row.device,
                row.steps,
                row.precision,
                row.text_s,
                row.step_s,
                row.vae_s,
                row.total_s,
                row.load_s,
                row.record_s,
                row.peak_mib,
                row.cpu_reference.as_ref().map_or("-".into(), |v| v.to_string()),
                row.step_ratio_to_cpu.map_or("-".into(), |r| format!("{r:.2}×")),
            )
        })?;
    }
    Ok(())
}

/// Our run; the device and every buffer are released before the reference runs.
fn measure(args: &GenArgs, env: &Environment, dtype: Dtype, size: usize) -> Result<Row> {
    let ctx = args.common.device.open(env)?;
    let start = Instant::now();
    let model = Sdxl::random_sdxl_base(&ctx, dtype)?;
    let load_s = start.elapsed().as_secs_f64();
    let job = bench_job(size, args.steps);
    model.check_sampling(&job.sampling)?;
    let start = Instant::now();
    let out =
        model.text_to_image(&job, &Guides::default(), &mut |done, total| eprintln!("{size}²: step {done}/{total}"))?;
    let total_s = start.elapsed().as_secs_f64();
    let t = &out.timings;
    let steps: Vec<f64> = t.steps.iter().map(|d| d.as_secs_f64()).collect();
    Ok(Row {
        device: ctx.info().name.clone(),
        size,
        steps: t.steps.len(),
        precision: crate::kernels::dtype_name(dtype).into(),
        load_s,
        text_s: t.text_encoding.as_secs_f64(),
        record_s: t.record.as_secs_f64(),
        step_s: steps_after_first(&steps).map_err(anyhow::Error::msg)?.median,
        vae_s: t.vae.as_secs_f64(),
        total_s,
        peak_mib: ctx.peak_bytes() as f64 / (1 << 20) as f64,
        ..Row::default()
    })
}

/// The benchmarks' generation: one prompt, no negative prompt, Euler, guidance 5, square.
pub(super) fn bench_job(size: usize, steps: usize) -> TextToImage {
    TextToImage {
        prompt: "white button mushrooms on brown compost, top-down photo".into(),
        negative_prompt: None,
        seed: 0,
        sampling: bench_sampling(size, steps),
    }
}

/// The benchmarks' sampling: Euler, guidance 5, `steps` steps, `size`² (`bench gen` and the
/// dataset benchmarks alike).
pub(super) fn bench_sampling(size: usize, steps: usize) -> Sampling {
    Sampling {
        steps,
        guidance_scale: 5.0,
        sampler: SamplerKind::Euler,
        schedule: Default::default(),
        width: size,
        height: size,
        size_conditioning: Default::default(),
        strength: None,
        prompt_syntax: Default::default(),
    }
}

/// What `tools/gen_cpu_reference.py` prints: each stage's seconds and each step's.
#[derive(serde::Deserialize, serde::Serialize)]
struct GenTimes {
    text_s: f64,
    steps: Vec<f64>,
    vae_s: f64,
    peak_mib: f64,
    torch: String,
    diffusers: String,
    threads: usize,
}

/// diffusers' step time (by the one step rule) and all it printed, as the row shows it.
fn reference(env: &Environment, size: usize, steps: usize) -> std::result::Result<(f64, serde_json::Value), String> {
    // The reference's tokenizers read vkdiff's built-in vocabulary, written where it can find it.
    let tokenizers = std::env::temp_dir().join(format!("vkdiff-bench-gen-tokenizers-{}", std::process::id()));
    let written =
        ["tokenizer", "tokenizer_2"].iter().try_for_each(|sub| ClipTokenizer::write_builtin(&tokenizers.join(sub)));
    let result = written.map_err(|e| e.to_string()).and_then(|()| {
        let configs = [SDXL_BASE_CONFIG, SDXL_CLIP_L_CONFIG, SDXL_BIGG_CONFIG, SDXL_VAE_CONFIG].map(String::from);
        let tokenizers = tokenizers.display().to_string();
        crate::cpu_reference::run_python_reference::<GenTimes, _>(
            env,
            REFERENCE,
            configs.into_iter().chain([tokenizers, size.to_string(), steps.to_string()]),
            None,
        )
    });
    let _ = std::fs::remove_dir_all(&tokenizers);
    let out = result?;
    let step_s = steps_after_first(&out.steps).map_err(|why| format!("{}: {why}", REFERENCE.path))?.median;
    Ok((step_s, serde_json::to_value(&out).map_err(|e| e.to_string())?))
}
