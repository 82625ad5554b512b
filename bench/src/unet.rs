//! `vkdiff bench unet`: one SDXL UNet evaluation (the real architecture, random weights) per
//! latent size, timed on the device, beside diffusers in the same run: on this machine's CPU, or
//! with `--reference-device cuda` on its NVIDIA GPU at the same precision.

use crate::kernels::{dtype_name, rand_tensor};
use crate::peaks;
use crate::profile::{self, by_kernel, KernelTime, TunedRow};
use anyhow::Result;
use std::time::{Duration, Instant};
use vkdiff_args::Precision;
use vkdiff_networks::{Checkpoint, UNet, UNetConfig, UNetInputs, SDXL_BASE_CONFIG};
use vkdiff_runtime::{Context, Dtype, Environment, Tensor};

const REFERENCE: crate::cpu_reference::Script = crate::cpu_reference::script!("unet_reference.py");

/// One untimed evaluation before the timed ones, on both sides: the best of them is the steady
/// state's, not the first touch of memory or kernels.
const WARM_UP: bool = true;

/// Where diffusers runs beside us.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ReferenceDevice {
    /// float32 on the CPU.
    Cpu,
    /// The CUDA GPU, at `--precision`.
    Cuda,
}

#[derive(clap::Args)]
pub struct UnetArgs {
    #[command(flatten)]
    common: crate::common::Common,
    /// Image sizes in pixels (square); the latent is 1/8 of it.
    #[arg(long, value_delimiter = ',', default_values_t = [512, 1024])]
    size: Vec<usize>,
    /// Batch (2 = one classifier-free-guidance step).
    #[arg(long, default_value_t = 2)]
    batch: usize,
    /// f16 (f32 arithmetic, matrix units where the GPU has them) or f32.
    #[arg(long, value_enum, default_value_t = Precision::F16)]
    precision: Precision,
    /// Timed evaluations per size; the best is reported.
    #[arg(long, default_value_t = 1)]
    samples: usize,
    /// Also time every dispatch of one more evaluation and list the kernels by device time.
    #[arg(long)]
    profile: bool,
    /// Where the diffusers reference runs.
    #[arg(long, value_enum, default_value_t = ReferenceDevice::Cpu)]
    reference_device: ReferenceDevice,
}

#[derive(serde::Serialize)]
struct Row {
    device: String,
    size: usize,
    batch: usize,
    precision: &'static str,
    /// The kernels the products ran on (`matrix units 16×16`, `tiled`, …).
    gemm_kernels: String,
    /// What the matrix units' trial at start found, where one ran.
    matrix_unit_trial: Option<String>,
    load_s: f64,
    record_s: f64,
    ms: f64,
    /// Matrix-product arithmetic of one evaluation, counted from the recorded dispatches.
    tflop: f64,
    /// Submissions in the fastest run (chunks of VKDIFF_SUBMIT_GFLOP, merged up to
    /// VKDIFF_SUBMIT_MERGE after the first run), and the longest one's time in it (what a GPU
    /// watchdog, 2 s on Windows, holds against).
    submissions: usize,
    longest_submission_ms: f64,
    tflops: f64,
    /// `tflops` as a share of the GPU's f16 matrix-unit peak ("unknown" off the table).
    matrix_peak_share: String,
    weights_mib: f64,
    peak_mib: f64,
    reference_ms: Option<f64>,
    reference_peak_mib: Option<f64>,
    /// What ran the reference, or why it could not run.
    reference: String,
    ratio_to_reference: Option<f64>,
    /// With `--profile`: device time per kernel, largest first.
    profile: Vec<KernelTime>,
    /// With `VKDIFF_TUNE=1`: each shape's candidates and the one it took.
    tuned: Vec<TunedRow>,
}

pub fn run(args: &UnetArgs, env: &Environment) -> Result<()> {
    let dtype = args.precision.dtype();
    let config = UNetConfig::sdxl_base();
    for &size in &args.size {
        vkdiff_args::ensure_usage(size % 32 == 0 && size > 0, || {
            format!("--size {size}: SDXL needs a multiple of 32 pixels")
        })?;
        let mut row = measure(args, env, &config, dtype, size)?;
        if !args.common.no_cpu_reference {
            match reference(env, size / 8, args) {
                Ok(r) => {
                    row.ratio_to_reference = Some(r.ms / row.ms);
                    let events = r.gpu_ms.as_deref().and_then(crate::cpu_reference::median);
                    let events = events.map_or(String::new(), |m| format!("; GPU median {m:.1} ms (CUDA events)"));
                    let what = format!("{}{events}; compiled {}", r.what, r.compiled.describe(1e3, "ms"));
                    (row.reference_ms, row.reference_peak_mib, row.reference) = (Some(r.ms), Some(r.peak_mib), what);
                }
                Err(why) => row.reference = format!("unavailable: {why}"),
            }
        }
        args.common.print(&row, |row| {
            format!(
                "{} | SDXL UNet {size}² batch {} {} on {}: {:.0} ms/eval, {:.2} TFLOP at {} ({} of the \
                    matrix peak) in {} submissions, the longest {:.0} ms (load {:.1} s, record {:.2} s), weights {:.0} \
                    MiB, peak {:.0} MiB | diffusers: {} | speed-up {}",
                row.device,
                row.batch,
                row.precision,
                row.gemm_kernels,
                row.ms,
                row.tflop,
                rate(row.tflops),
                row.matrix_peak_share,
                row.submissions,
                row.longest_submission_ms,
                row.load_s,
                row.record_s,
                row.weights_mib,
                row.peak_mib,
                row.reference_ms.map_or(row.reference.clone(), |ms| format!(
                    "{ms:.0} ms, peak {:.0} MiB ({})",
                    row.reference_peak_mib.unwrap_or(0.0),
                    row.reference
                )),
                row.ratio_to_reference.map_or("-".into(), |r| format!("{r:.2}×")),
            ) + &row.matrix_unit_trial.as_ref().map_or(String::new(), |t| format!("\n  matrix-unit trial: {t}"))
                + &profile::lines(&row.profile)
                + &profile::tuned_lines(&row.tuned)
        })?;
    }
    Ok(())
}

/// Our evaluation; the device and every buffer are released before the reference runs.
fn measure(args: &UnetArgs, env: &Environment, config: &UNetConfig, dtype: Dtype, size: usize) -> Result<Row> {
    let ctx = args.common.device.open(env)?;
    let start = Instant::now();
    let ckpt = Checkpoint::random(&ctx, dtype, 0);
    let unet = UNet::load(config, &ckpt)?;
    let load_s = start.elapsed().as_secs_f64();
    let weights = ctx.live_bytes();
    let tensors = RandomInputs::new(&ctx, config, dtype, args.batch, size)?;
    let timed = time_unet(&unet, &tensors.inputs(), WARM_UP, args.samples.max(1))?;
    let best = timed.seconds.iter().copied().fold(f64::INFINITY, f64::min);
    let profile = if args.profile { profile(&ctx, &unet, &tensors.inputs())? } else { Vec::new() };
    let mib = |b: u64| b as f64 / (1 << 20) as f64;
    let tflop = timed.flops / 1e12;
    Ok(Row {
        device: ctx.info().name.clone(),
        size,
        batch: args.batch,
        precision: dtype_name(dtype),
        gemm_kernels: peaks::family_label(&ctx, dtype),
        matrix_unit_trial: peaks::trial_label(&ctx),
        load_s,
        record_s: timed.record_s,
        ms: best * 1e3,
        tflop,
        submissions: timed.fastest_submissions.len(),
        longest_submission_ms: timed.fastest_submissions.iter().max().map_or(0.0, |d| d.as_secs_f64() * 1e3),
        tflops: tflop / best,
        matrix_peak_share: peaks::share_label(&ctx, tflop * 1e12 / best),
        weights_mib: mib(weights),
        peak_mib: mib(ctx.peak_bytes()),
        reference_ms: None,
        reference_peak_mib: None,
        reference: String::new(),
        ratio_to_reference: None,
        profile,
        tuned: profile::tuned(&ctx),
    })
}

/// A UNet's inputs at `size`² pixels: random latents and text, timestep 500, size conditioning.
pub(crate) struct RandomInputs {
    sample: Tensor,
    timesteps: Tensor,
    context: Tensor,
    text: Tensor,
    ids: Tensor,
}

impl RandomInputs {
    pub(crate) fn new(ctx: &Context, config: &UNetConfig, dtype: Dtype, batch: usize, size: usize) -> Result<Self> {
        let h = size / 8;
        let text_dim =
            config.projection_class_embeddings_input_dim.unwrap_or(0) - 6 * config.addition_time_embed_dim.unwrap_or(0);
        let px = size as f32;
        Ok(RandomInputs {
            sample: rand_tensor(ctx, &[batch, h, h, config.in_channels], dtype, 1)?,
            timesteps: ctx.upload(&[batch], Dtype::F32, &vec![500.0; batch])?,
            context: rand_tensor(ctx, &[batch, 77, config.cross_attention_dim], dtype, 2)?,
            text: rand_tensor(ctx, &[batch, text_dim], dtype, 3)?,
            ids: ctx.upload(&[batch, 6], Dtype::F32, &[px, px, 0.0, 0.0, px, px].repeat(batch))?,
        })
    }

    pub(crate) fn inputs(&self) -> UNetInputs<'_> {
        UNetInputs {
            sample: &self.sample,
            timesteps: &self.timesteps,
            encoder_hidden_states: &self.context,
            added: Some((&self.text, &self.ids)),
            control: None,
            ip: &[],
        }
    }
}

/// One evaluation recorded once and run `runs` times (after one untimed run with `warm_up`).
pub(crate) struct UnetRuns {
    pub record_s: f64,
    /// Recording and the first run: kernels compiled, memory first touched.
    pub first_s: f64,
    pub seconds: Vec<f64>,
    /// Matrix-product arithmetic of one evaluation, counted from the recorded dispatches.
    pub flops: f64,
    /// The submissions of the fastest timed run (what a GPU watchdog holds against).
    pub fastest_submissions: Vec<Duration>,
}

pub(crate) fn time_unet(unet: &UNet, inputs: &UNetInputs, warm_up: bool, runs: usize) -> Result<UnetRuns> {
    let start = Instant::now();
    let pass = unet.record(inputs)?;
    pass.project_conditioning()?;
    let record_s = start.elapsed().as_secs_f64();
    if warm_up {
        pass.run_submissions()?;
    }
    let first_s = start.elapsed().as_secs_f64();
    let (mut seconds, mut fastest) = (Vec::new(), Vec::new());
    for _ in 0..runs {
        let start = Instant::now();
        let submissions = pass.run_submissions()?;
        let s = start.elapsed().as_secs_f64();
        if seconds.iter().all(|&b| s < b) {
            fastest = submissions;
        }
        seconds.push(s);
    }
    let out = pass.output.download()?;
    anyhow::ensure!(out.iter().all(|v| v.is_finite()), "the UNet output holds NaN or infinity");
    // Without a warm-up, the first timed run is the first run.
    let first_s = if warm_up { first_s } else { first_s + seconds.first().copied().unwrap_or(0.0) };
    Ok(UnetRuns { record_s, first_s, seconds, flops: pass.flops(), fastest_submissions: fastest })
}

/// Device time per kernel over one evaluation recorded with timestamps, largest first.
fn profile(ctx: &Context, unet: &UNet, inputs: &UNetInputs) -> Result<Vec<KernelTime>> {
    ctx.set_profiling(true);
    let pass = unet.record(inputs);
    ctx.set_profiling(false);
    let pass = pass?;
    pass.project_conditioning()?;
    Ok(by_kernel(pass.run_profiled()?))
}

/// diffusers: milliseconds of each timed evaluation by wall-clock (the best first) and on CUDA
/// by CUDA events, its peak memory, what ran it, and the same model compiled.
pub(crate) struct Reference {
    pub ms: f64,
    pub times_ms: Vec<f64>,
    pub gpu_ms: Option<Vec<f64>>,
    pub peak_mib: f64,
    pub what: String,
    pub compiled: crate::cpu_reference::Compiled,
}

fn reference(env: &Environment, latent: usize, args: &UnetArgs) -> std::result::Result<Reference, String> {
    let cuda = (args.reference_device == ReferenceDevice::Cuda).then(|| args.precision.dtype());
    diffusers_unet(env, SDXL_BASE_CONFIG, latent, args.batch, args.samples.max(1), WARM_UP, cuda)
}

/// diffusers' UNet2DConditionModel of `config` (random weights) on the CPU in f32, or with
/// `cuda` on the CUDA GPU at that precision, `samples` timed evaluations (after an untimed one
/// with `warm_up`, on either device, as vkdiff's side did).
pub(crate) fn diffusers_unet(
    env: &Environment,
    config: &str,
    latent: usize,
    batch: usize,
    samples: usize,
    warm_up: bool,
    cuda: Option<Dtype>,
) -> std::result::Result<Reference, String> {
    let mut script_args = [latent, latent, batch, samples, usize::from(warm_up)].map(|n| n.to_string()).to_vec();
    script_args.insert(0, config.to_string());
    if let Some(dtype) = cuda {
        script_args.extend(["cuda".to_string(), dtype_name(dtype).to_string()]);
    }
    let out: UnetTimes = crate::cpu_reference::run_python_reference(env, REFERENCE, script_args, None)?;
    let gpu_ms = out.gpu.map(|g| g.iter().map(|s| s * 1e3).collect());
    let what = out.run.label();
    Ok(Reference { ms: out.ms, times_ms: out.times_ms, gpu_ms, peak_mib: out.peak_mib, what, compiled: out.compiled })
}

/// What `tools/unet_reference.py` prints.
#[derive(serde::Deserialize)]
struct UnetTimes {
    ms: f64,
    times_ms: Vec<f64>,
    /// Seconds by CUDA events; null on the CPU.
    #[serde(deserialize_with = "Option::deserialize")]
    gpu: Option<Vec<f64>>,
    peak_mib: f64,
    compiled: crate::cpu_reference::Compiled,
    #[serde(flatten)]
    run: crate::cpu_reference::DiffusersRun,
}

/// "71.5 TFLOP/s", or "38 GFLOP/s" below one TFLOP/s (CPU devices would read "0.0 TFLOP/s").
pub(crate) fn rate(tflops: f64) -> String {
    if tflops >= 1.0 {
        format!("{tflops:.1} TFLOP/s")
    } else {
        format!("{:.0} GFLOP/s", tflops * 1e3)
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn rates_below_a_teraflop_read_in_gigaflops() {
        assert_eq!(super::rate(71.46), "71.5 TFLOP/s");
        assert_eq!(super::rate(0.0383), "38 GFLOP/s");
    }
}
