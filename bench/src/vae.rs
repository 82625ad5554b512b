//! `vkdiff bench vae`: SDXL's VAE decoder (real architecture, random weights; f32 as its
//! `force_upcast` asks, or f16 as the fp16-fix VAE's config allows) decoding whole and in
//! diffusers' tiles, with each decode's activation
//! memory (the context's peak less the weights) beside the estimate the memory plan uses; the
//! whole decode is the tiled one's reference, in the same run. With `--reference-device`,
//! diffusers decodes the same size there after vkdiff's device is released
//! (`tools/vae_reference.py`).

use crate::kernels::dtype_name;
use crate::profile::{self, by_kernel, KernelTime};
use crate::unet::ReferenceDevice;
use anyhow::Result;
use std::time::Instant;
use vkdiff_args::Precision;
use vkdiff_networks::{AutoencoderKl, Checkpoint, VaeConfig, VaeTiling, SDXL_VAE_CONFIG};
use vkdiff_runtime::{Dtype, Environment, HostStats};

#[derive(clap::Args)]
pub struct VaeArgs {
    #[command(flatten)]
    device: vkdiff_args::DeviceArgs,
    /// Image side in pixels (square).
    #[arg(long, default_value_t = 512)]
    size: usize,
    /// f32 (SDXL's VAE, which asks for it), or f16 (the fp16-fix VAE's config: `force_upcast` false).
    #[arg(long, value_enum, default_value_t = Precision::F32)]
    precision: Precision,
    /// Time this VAE instead of random weights (a folder, a single file, a Hugging Face id); it
    /// decodes in f16 only where its config allows. A reference times SDXL's architecture at the
    /// same precision.
    #[arg(long, value_name = "DIR|FILE|ID")]
    vae: Option<std::path::PathBuf>,
    /// Tile side in pixels for the tiled decode (a multiple of 32).
    #[arg(long, default_value_t = 256)]
    tile: usize,
    /// Decodes of each kind; the fastest is reported (the first compiles the kernels).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    samples: u32,
    /// Also time every dispatch of one more whole decode and list the kernels by device time.
    #[arg(long)]
    profile: bool,
    /// Also time diffusers' whole decode there, at `--precision` (f32: on CUDA also with TF32
    /// convolutions, torch's default).
    #[arg(long, value_enum)]
    reference_device: Option<ReferenceDevice>,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
}

#[derive(serde::Serialize)]
struct Decode {
    tile: Option<usize>,
    seconds: f64,
    activations_mib: f64,
    estimate_mib: f64,
    /// The last decode's host work besides waiting for the device.
    host: Host,
}

/// Device tensors' buffers fresh from the driver or reused idle ones, the host's time in the
/// driver's allocation calls (staging buffers' too), and its time recording (allocations made
/// meanwhile included).
#[derive(serde::Serialize)]
struct Host {
    fresh_buffers: u64,
    fresh_mib: f64,
    reused_buffers: u64,
    allocation_ms: f64,
    recording_ms: f64,
}

impl Host {
    fn of(stats: HostStats) -> Host {
        Host {
            fresh_buffers: stats.fresh,
            fresh_mib: stats.fresh_bytes as f64 / (1 << 20) as f64,
            reused_buffers: stats.reused,
            allocation_ms: stats.allocation_seconds * 1e3,
            recording_ms: stats.recording_seconds * 1e3,
        }
    }
}

#[derive(serde::Serialize)]
struct Row {
    device: String,
    size: usize,
    precision: &'static str,
    weights_mib: f64,
    whole: Decode,
    tiled: Decode,
    /// Tiled activations over whole ones.
    memory_ratio: f64,
    /// With `--profile`: device time per kernel of a whole decode, largest first.
    profile: Vec<KernelTime>,
    /// With `--reference-device`: diffusers' whole decode, or why it could not run.
    reference: Option<std::result::Result<Reference, String>>,
}

/// diffusers' fastest whole decode, in the precision's own arithmetic, and (f32 on CUDA) with
/// torch's default of TF32 convolutions.
#[derive(serde::Serialize)]
pub(crate) struct Reference {
    pub seconds: f64,
    /// Each timed decode, in the precision's own arithmetic.
    pub times: Vec<f64>,
    pub seconds_tf32: Option<f64>,
    /// Each timed decode by CUDA events (CUDA only).
    pub gpu: Option<Vec<f64>>,
    pub peak_mib: f64,
    pub what: String,
    pub compiled: crate::cpu_reference::Compiled,
}

impl Reference {
    /// diffusers' time over ours for each of its modes, as the UNet bench's speed-up.
    fn describe(&self, ours: f64) -> String {
        let tf32 = self.seconds_tf32.map_or(String::new(), |s| {
            format!(", {s:.2} s with TF32 convolutions (torch's default; speed-up {:.2}×)", s / ours)
        });
        let events = self.gpu.as_deref().and_then(crate::cpu_reference::median);
        let events = events.map_or(String::new(), |m| format!(", GPU median {m:.3} s (CUDA events)"));
        format!(
            "{:.2} s (speed-up {:.2}×){tf32}{events}, peak {:.0} MiB ({}); compiled {}",
            self.seconds,
            self.seconds / ours,
            self.peak_mib,
            self.what,
            self.compiled.describe(1.0, "s")
        )
    }
}

const REFERENCE: crate::cpu_reference::Script = crate::cpu_reference::script!("vae_reference.py");

fn reference(
    env: &Environment,
    config: &str,
    args: &VaeArgs,
    device: ReferenceDevice,
) -> std::result::Result<Reference, String> {
    diffusers_vae(env, config, args.size, args.samples as usize, device, args.precision.dtype())
}

/// diffusers' whole decode of a `size`² image with `config` (random weights), `samples` times
/// after a warm-up, on `device` in `dtype`.
pub(crate) fn diffusers_vae(
    env: &Environment,
    config: &str,
    size: usize,
    samples: usize,
    device: ReferenceDevice,
    dtype: Dtype,
) -> std::result::Result<Reference, String> {
    let device = match device {
        ReferenceDevice::Cpu => "cpu",
        ReferenceDevice::Cuda => "cuda",
    };
    let script_args = [config, &size.to_string(), &samples.to_string(), device, dtype_name(dtype)].map(str::to_string);
    let out: VaeTimes = crate::cpu_reference::run_python_reference(env, REFERENCE, script_args, None)?;
    Ok(Reference {
        seconds: out.seconds,
        times: out.times,
        seconds_tf32: out.seconds_tf32,
        gpu: out.gpu,
        peak_mib: out.peak_mib,
        what: out.run.label(),
        compiled: out.compiled,
    })
}

/// What `tools/vae_reference.py` prints; `seconds_tf32` only for float32 on CUDA.
#[derive(serde::Deserialize)]
struct VaeTimes {
    seconds: f64,
    times: Vec<f64>,
    /// Seconds by CUDA events; null on the CPU.
    #[serde(deserialize_with = "Option::deserialize")]
    gpu: Option<Vec<f64>>,
    seconds_tf32: Option<f64>,
    peak_mib: f64,
    compiled: crate::cpu_reference::Compiled,
    #[serde(flatten)]
    run: crate::cpu_reference::DiffusersRun,
}

/// The latents a `size`² decode starts from: a fixed pattern, the same in every run.
fn latents(vae: &AutoencoderKl, size: usize) -> (Vec<f32>, [usize; 4]) {
    let h = size / vae.config().downscale();
    ((0..h * h * 4).map(|i| ((i * 7919) % 1000) as f32 / 500.0 - 1.0).collect(), [1, h, h, 4])
}

/// Whole decodes of a `size`² image: the first (kernels compiled, memory first touched) and
/// `runs` more, in seconds.
pub(crate) fn time_whole_decode(vae: &AutoencoderKl, size: usize, runs: usize) -> Result<(f64, Vec<f64>)> {
    let (latents, shape) = latents(vae, size);
    let start = Instant::now();
    vae.decode(&latents, shape)?;
    let first = start.elapsed().as_secs_f64();
    let mut times = Vec::new();
    for _ in 0..runs {
        let start = Instant::now();
        vae.decode(&latents, shape)?;
        times.push(start.elapsed().as_secs_f64());
    }
    Ok((first, times))
}

pub fn run(args: &VaeArgs, env: &Environment) -> Result<()> {
    let resolve = |v: &std::path::Path| vkdiff_args::resolve_model("--vae", v, vkdiff_args::Wants::Either, env);
    let vae = args.vae.as_deref().map(resolve).transpose()?;
    let mut config: serde_json::Value = serde_json::from_str(SDXL_VAE_CONFIG)?;
    // f16 is the fp16-fix VAE: SDXL's architecture, with a config that does not ask for f32.
    let upcast = match &vae {
        Some(path) => AutoencoderKl::sdxl_config(path)?.force_upcast || matches!(args.precision, Precision::F32),
        None => matches!(args.precision, Precision::F32),
    };
    config["force_upcast"] = upcast.into();
    let config = config.to_string();
    let mut row = measure(args, env, &config, vae.as_deref())?;
    row.reference = args.reference_device.map(|device| reference(env, &config, args, device));
    if args.json {
        println!("{}", serde_json::to_string(&row)?);
    } else {
        let line = |d: &Decode| {
            format!(
                "{:.2} s, activations {:.0} MiB (plan's estimate {:.0} MiB); the last decode recorded for {:.1} \
                 ms, took {} buffers fresh ({:.0} MiB, {:.1} ms in the driver's allocation calls) and reused {}",
                d.seconds,
                d.activations_mib,
                d.estimate_mib,
                d.host.recording_ms,
                d.host.fresh_buffers,
                d.host.fresh_mib,
                d.host.allocation_ms,
                d.host.reused_buffers
            )
        };
        let reference = match &row.reference {
            None => String::new(),
            Some(Ok(r)) => format!(" | diffusers whole: {}", r.describe(row.whole.seconds)),
            Some(Err(why)) => format!(" | diffusers: unavailable: {why}"),
        };
        println!(
            "{} | SDXL VAE decode {}² {}, weights {:.0} MiB | whole: {} | {}-px tiles: {} | tiled/whole memory {:.2}{reference}{}",
            row.device,
            row.size,
            row.precision,
            row.weights_mib,
            line(&row.whole),
            args.tile,
            line(&row.tiled),
            row.memory_ratio,
            profile::lines(&row.profile)
        );
    }
    Ok(())
}

/// vkdiff's decodes (of the VAE at `path`, else random weights of `config`); the device and
/// every buffer are released before a reference runs.
fn measure(args: &VaeArgs, env: &Environment, config: &str, path: Option<&std::path::Path>) -> Result<Row> {
    let ctx = args.device.open(env)?;
    let config: VaeConfig = serde_json::from_str(config)?;
    let vae = match path {
        Some(path) => AutoencoderKl::load_sdxl(&ctx, path, args.precision.dtype())?,
        None => AutoencoderKl::load(&ctx, config, &Checkpoint::random(&ctx, args.precision.dtype(), 0))?,
    };
    let dtype = vae.dtype();
    let tiling = VaeTiling { tile: args.tile };
    vae.config().check_tiling(tiling)?;
    let weights = ctx.live_bytes();
    let (latents, shape) = latents(&vae, args.size);
    let mib = |b: u64| b as f64 / (1 << 20) as f64;
    let decode = |tile: Option<VaeTiling>| -> Result<Decode> {
        ctx.reset_peak();
        let mut seconds = f64::INFINITY;
        let mut host = HostStats::default();
        for _ in 0..args.samples {
            let (start, before) = (Instant::now(), ctx.host_stats());
            match tile {
                Some(t) => vae.decode_tiled(&latents, shape, t)?,
                None => vae.decode(&latents, shape)?,
            };
            seconds = seconds.min(start.elapsed().as_secs_f64());
            host = ctx.host_stats().since(&before);
        }
        let side = tile.map_or(args.size, |t| t.tile.min(args.size));
        Ok(Decode {
            tile: tile.map(|t| t.tile),
            seconds,
            activations_mib: mib(ctx.peak_bytes() - weights),
            estimate_mib: mib(vae.config().decode_bytes(vae.dtype(), 1, side, side)),
            host: Host::of(host),
        })
    };
    let whole = decode(None)?;
    let tiled = decode(Some(tiling))?;
    let profile = if args.profile {
        let (decoded, timings) = ctx.profiled(|| vae.decode(&latents, shape));
        decoded?;
        by_kernel(timings)
    } else {
        Vec::new()
    };
    Ok(Row {
        device: ctx.info().name.clone(),
        size: args.size,
        precision: dtype_name(dtype),
        weights_mib: mib(weights),
        memory_ratio: tiled.activations_mib / whole.activations_mib,
        whole,
        tiled,
        profile,
        reference: None,
    })
}
