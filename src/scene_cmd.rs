//! `vkdiff scene` and `vkdiff bench scene`: arguments and the glue to vkdiff-render.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, ValueEnum};
use vkdiff_render::bed::BedConfig;
use vkdiff_render::bench::bench_scene;
use vkdiff_render::control::ControlDepth;
use vkdiff_render::output::{write_dataset, write_scene, OutputOptions};
use vkdiff_render::scene::SceneConfig;
use vkdiff_render::with_threads;

/// Settings shared by `scene` and `bench scene`.
#[derive(Args, Debug)]
pub struct SceneSettings {
    /// Seed of the (first) scene (`dataset`: also of every image's seed); the same seed and settings
    /// give byte-identical files.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[arg(long, default_value_t = 1920)]
    width: u32,
    #[arg(long, default_value_t = 1080)]
    height: u32,
    /// Mushrooms proposed per m² of bed (the default gives about 145 visible per 1920×1080 frame).
    #[arg(long, default_value_t = BedConfig::default().density, allow_negative_numbers = true)]
    density: f64,
    /// Share of mushrooms growing in clumps, 0 (spread evenly) to 1.
    #[arg(long, default_value_t = BedConfig::default().clumping.clustered_fraction, allow_negative_numbers = true)]
    clumping: f64,
    /// Worker threads (0: one per core). Output does not depend on it.
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
}

impl SceneSettings {
    pub fn config(&self) -> SceneConfig {
        let mut bed = BedConfig { density: self.density, ..BedConfig::default() };
        bed.clumping.clustered_fraction = self.clumping;
        SceneConfig { width: self.width, height: self.height, bed, ..SceneConfig::default() }
    }
}

/// How each frame is cut into square crops; shared by `scene` and `dataset`.
#[derive(Args, Debug)]
pub struct CropArgs {
    /// Square crops per scene (`scene`: under DIR/crops/<k>/; `dataset`: one image each, and 0
    /// makes one image of the whole frame, cut centred to the sides the model makes, e.g.
    /// 1920×1080 → 1920×1056 for SDXL's multiples of 32).
    #[arg(long, default_value_t = 0)]
    pub crops: usize,
    #[arg(long, default_value_t = 1024)]
    pub crop_size: u32,
    /// Drop an instance from a crop when less than this share of its visible pixels falls inside.
    #[arg(long, default_value_t = 0.1, allow_negative_numbers = true)]
    pub crop_min_fraction: f64,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
pub(crate) enum ControlMode {
    /// Per-image min–max of 1/z (as MiDaS-style depth estimators give), near = bright.
    Inverse,
    /// Per-image min–max of z, reversed so near = bright.
    Linear,
}

impl From<ControlMode> for ControlDepth {
    fn from(mode: ControlMode) -> ControlDepth {
        match mode {
            ControlMode::Inverse => ControlDepth::Inverse,
            ControlMode::Linear => ControlDepth::Linear,
        }
    }
}

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

/// Frames per second of the scene pipeline at the given size, stage by stage.
#[derive(Args, Debug)]
pub struct BenchSceneArgs {
    #[command(flatten)]
    settings: SceneSettings,
    /// Timed frames (seeds N..N+frames-1), after one warm-up frame.
    #[arg(long, default_value_t = 20)]
    frames: usize,
}

pub fn run_bench_scene(args: BenchSceneArgs) -> anyhow::Result<()> {
    let config = args.settings.config();
    let report = with_threads(args.settings.threads, || bench_scene(args.settings.seed, args.frames, &config))
        .context("starting the worker threads")??;
    println!("{report}");
    Ok(())
}
