//! `vkdiff bench scene`: frames per second of depth + masks + COCO, stage by stage, against the
//! paper's Blender.

use anyhow::Context;
use clap::Args;
use vkdiff_args::SceneSettings;
use vkdiff_render::bench::bench_scene;
use vkdiff_render::with_threads;

/// Frames per second of the scene pipeline at the given size, stage by stage.
#[derive(Args, Debug)]
pub struct BenchSceneArgs {
    #[command(flatten)]
    settings: SceneSettings,
    /// Timed frames (seeds N..N+frames-1), after one warm-up frame.
    #[arg(long, default_value_t = 20)]
    frames: usize,
}

pub fn run(args: &BenchSceneArgs) -> anyhow::Result<()> {
    let config = args.settings.config();
    let report = with_threads(args.settings.threads, || bench_scene(args.settings.seed, args.frames, &config))
        .context("starting the worker threads")??;
    println!("{report}");
    Ok(())
}
