//! `vkdiff bench vae`: SDXL's VAE decoder (real architecture, random weights, f32 as its
//! `force_upcast` asks) decoding whole and in diffusers' tiles, with each decode's activation
//! memory (the context's peak less the weights) beside the estimate the memory plan uses; the
//! whole decode is the tiled one's reference, in the same run.

use crate::profile::{self, by_kernel, KernelTime};
use anyhow::Result;
use std::time::Instant;
use vkdiff_networks::{AutoencoderKl, Checkpoint, VaeConfig, VaeTiling, SDXL_VAE_CONFIG};
use vkdiff_runtime::{Context, Dtype};

#[derive(clap::Args)]
pub struct VaeArgs {
    #[command(flatten)]
    device: vkdiff_args::DeviceArgs,
    /// Image side in pixels (square).
    #[arg(long, default_value_t = 512)]
    size: usize,
    /// Tile side in pixels for the tiled decode (a multiple of 32).
    #[arg(long, default_value_t = 256)]
    tile: usize,
    /// Decodes of each kind; the fastest is reported (the first compiles the kernels).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    samples: u32,
    /// Also time every dispatch of one more whole decode and list the kernels by device time.
    #[arg(long)]
    profile: bool,
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
}

#[derive(serde::Serialize)]
struct Row {
    device: String,
    size: usize,
    weights_mib: f64,
    whole: Decode,
    tiled: Decode,
    /// Tiled activations over whole ones.
    memory_ratio: f64,
    /// With `--profile`: device time per kernel of a whole decode, largest first.
    profile: Vec<KernelTime>,
}

pub fn run(args: &VaeArgs) -> Result<()> {
    let ctx = Context::new(&args.device.choice())?;
    let config: VaeConfig = serde_json::from_str(SDXL_VAE_CONFIG)?;
    let vae = AutoencoderKl::load(&ctx, config, &Checkpoint::random(&ctx, Dtype::F32, 0))?;
    let tiling = VaeTiling { tile: args.tile };
    vae.check_tiling(tiling)?;
    let weights = ctx.live_bytes();
    let h = args.size / vae.config().downscale();
    let latents: Vec<f32> = (0..h * h * 4).map(|i| ((i * 7919) % 1000) as f32 / 500.0 - 1.0).collect();
    let mib = |b: u64| b as f64 / (1 << 20) as f64;
    let decode = |tile: Option<VaeTiling>| -> Result<Decode> {
        ctx.reset_peak();
        let mut seconds = f64::INFINITY;
        for _ in 0..args.samples {
            let start = Instant::now();
            match tile {
                Some(t) => vae.decode_tiled(&latents, [1, h, h, 4], t)?,
                None => vae.decode(&latents, [1, h, h, 4])?,
            };
            seconds = seconds.min(start.elapsed().as_secs_f64());
        }
        let side = tile.map_or(args.size, |t| t.tile.min(args.size));
        Ok(Decode {
            tile: tile.map(|t| t.tile),
            seconds,
            activations_mib: mib(ctx.peak_bytes() - weights),
            estimate_mib: mib(vae.decode_bytes(1, side, side)),
        })
    };
    let whole = decode(None)?;
    let tiled = decode(Some(tiling))?;
    let profile = if args.profile {
        let (decoded, timings) = ctx.profiled(|| vae.decode(&latents, [1, h, h, 4]));
        decoded?;
        by_kernel(timings)
    } else {
        Vec::new()
    };
    let row = Row {
        device: ctx.info().name.clone(),
        size: args.size,
        weights_mib: mib(weights),
        memory_ratio: tiled.activations_mib / whole.activations_mib,
        whole,
        tiled,
        profile,
    };
    if args.json {
        println!("{}", serde_json::to_string(&row)?);
    } else {
        let line = |d: &Decode| {
            format!(
                "{:.2} s, activations {:.0} MiB (plan's estimate {:.0} MiB)",
                d.seconds, d.activations_mib, d.estimate_mib
            )
        };
        println!(
            "{} | SDXL VAE decode {}² f32, weights {:.0} MiB | whole: {} | {}-px tiles: {} | tiled/whole memory {:.2}{}",
            row.device,
            row.size,
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
