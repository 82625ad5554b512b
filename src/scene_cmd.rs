//! `vkdiff scene`: procedural mushroom beds written by vkdiff-render.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use vkdiff_args::{ControlMode, CropArgs, SceneSettings};
use vkdiff_render::output::{write_dataset, write_scene, OutputOptions};
use vkdiff_render::with_threads;

/// Render procedural mushroom beds: depth.exr, instances.png, COCO annotations, camera,
/// ControlNet depth image and a preview, optionally with crops.
#[derive(Args, Debug)]
pub struct SceneArgs {
    #[command(flatten)]
    settings: SceneSettings,
    /// Output folder (with --count > 1: the folder that holds one subfolder per seed).
    #[arg(long)]
    out: PathBuf,
    /// Number of scenes, seeds N..N+M-1, written in parallel into numbered subfolders; folders
    /// already there are complete (they appear atomically) and are skipped.
    #[arg(long, default_value_t = 1)]
    count: u64,
    #[command(flatten)]
    crops: CropArgs,
    /// How control.png maps depth to brightness.
    #[arg(long, value_enum, default_value_t = ControlMode::Inverse)]
    control_depth: ControlMode,
    /// Replace existing output folders.
    #[arg(long)]
    force: bool,
}

pub fn run_scene(args: SceneArgs) -> anyhow::Result<()> {
    let config = args.settings.config();
    let options = OutputOptions {
        crops: args.crops.crops,
        crop_size: args.crops.crop_size,
        crop_min_fraction: args.crops.crop_min_fraction,
        control: args.control_depth.into(),
        replace: args.force,
    };
    let seed = args.settings.seed;
    with_threads(args.settings.threads, || -> anyhow::Result<()> {
        if args.count == 1 {
            write_scene(&args.out, seed, &config, &options)?;
            println!("wrote scene {seed} to {}", args.out.display());
        } else {
            let report = write_dataset(&args.out, seed, args.count, &config, &options)?;
            println!("wrote {} scenes to {} ({} already there)", report.written, args.out.display(), report.skipped);
        }
        Ok(())
    })
    .context("starting the worker threads")?
}
