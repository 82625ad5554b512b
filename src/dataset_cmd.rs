//! `vkdiff dataset`: scenes made into photoreal, exactly annotated training images; and
//! `vkdiff dataset merge DIR`.

use anyhow::{Context as _, Result};
use clap::{Args, Subcommand};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};
use vkdiff_args::Progress;
use vkdiff_args::{dataset_flag, CropArgs, SceneSettings};
use vkdiff_args::{ModelArgs, SamplingArgs};
use vkdiff_dataset::{
    merge, parse_size, read_prompts, size, stop_on_signals, Crops, DatasetEvent, DatasetJob, DatasetSettings, Finish,
    Merged, ProceduralBed, Progress as Event, RegionFlags, RenderedScenes, Report, RunOptions, SceneSource,
    ShardRequest, VersionChange, DEFAULT_FAR,
};
use vkdiff_pipeline::{recipe_warnings, Sampling};
use vkdiff_render::control::edges::DEFAULT_DEPTH_JUMP;
use vkdiff_render::control::ControlKind;

/// Render scenes and make each into photoreal images with exact masks: one folder with the
/// images, their depth, control images and instance masks, and COCO annotations. Resumable and
/// shardable; `vkdiff dataset merge DIR` joins the shards' parts.
#[derive(Args, Debug)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct DatasetArgs {
    #[command(subcommand)]
    command: Option<DatasetCommand>,
    /// Dataset folder; a folder made with the same settings is resumed.
    #[arg(long, required = true)]
    out: Option<PathBuf>,
    /// Scenes (seeds --seed … --seed + count − 1); images = count × max(crops, 1) [default: 1, or
    /// with --scenes every scene there].
    #[arg(long)]
    count: Option<u64>,
    /// Scenes rendered elsewhere instead of the procedural mushroom bed: a folder of scene folders
    /// (depth.exr or depth.png, instances.png, categories.json, shaded.png, prompt.txt; what
    /// `vkdiff scene` writes) or of BlenderProc's .hdf5 files, taken in name order.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["width", "height", "density", "clumping"])]
    scenes: Option<PathBuf>,
    /// With --scenes: the category of every instance of a scene folder without categories.json.
    #[arg(long, default_value = "object", requires = "scenes")]
    category: String,
    /// With --scenes: depth at or past this value (and infinite, NaN, zero or negative depth) is
    /// background; renderers write a far value there (BlenderProc: 1e10).
    #[arg(long, default_value_t = DEFAULT_FAR, requires = "scenes")]
    far: f32,
    #[command(flatten)]
    scene: SceneSettings,
    #[command(flatten)]
    crops: CropArgs,
    #[command(flatten)]
    model: ModelArgs,
    /// A prompt; repeat it for several, one chosen per image from its seed. A prompt may be a
    /// template, expanded per image from its seed: {wet|dry}, {3::wet|dry}, __soil__,
    /// {category}, {categories} (docs/dataset.md).
    #[arg(long)]
    prompt: Vec<String>,
    /// A file of prompts, one a line (blank lines skipped), added to any --prompt.
    #[arg(long)]
    prompts: Option<PathBuf>,
    /// The folder of the wildcard files the templates name: __soil__ is a line of DIR/soil.txt.
    #[arg(long, value_name = "DIR")]
    wildcards: Option<PathBuf>,
    #[command(flatten)]
    sampling: SamplingArgs,
    /// A style image for --ip-adapter; repeat it for one set of several.
    #[arg(long, requires = "ip_adapter")]
    ip_image: Vec<PathBuf>,
    /// A set of style images, comma-separated; repeat it for several sets, one chosen per image
    /// from its seed.
    #[arg(long, requires = "ip_adapter")]
    ip_set: Vec<String>,
    /// img2img from the scene: each image starts from its crop's shaded render (compost brown,
    /// mushrooms white, lit from the depth; kept as init/NNNNNN.png) at this strength, as
    /// `vkdiff gen --init-image` does, instead of from noise.
    #[arg(long)]
    init_strength: Option<f64>,
    /// The scenes' shaded renders as the images (compost brown, mushrooms white, lit from the
    /// depth): the baseline set, with no model and no GPU. Each image is byte for byte the init/
    /// file of a diffusion run with the same scene flags; an uncropped frame is cut to multiples
    /// of 8, as SDXL's.
    #[arg(long)]
    render_only: bool,
    /// More controls made from each image's labels beside its depth control, comma-separated:
    /// edges, segmentation, normals (control/NNNNNN.<kind>.png; docs/controls.md).
    #[arg(long, value_delimiter = ',', value_parser = parse_control)]
    controls: Vec<ControlKind>,
    /// With --controls edges or normals: a depth jump larger than this fraction of the nearer
    /// depth is an edge.
    #[arg(long, default_value_t = DEFAULT_DEPTH_JUMP)]
    edge_depth_jump: f32,
    /// A category's own prompt, as NAME=TEXT (repeat it): SDXL sees it where the category's
    /// masks are and the scene's prompt elsewhere (a categories.json `"prompt"` does the same;
    /// this wins). Each costs one more UNet row per image.
    #[arg(long, value_parser = parse_named_text, value_name = "NAME=TEXT")]
    category_prompt: Vec<(String, String)>,
    /// A category's own img2img strength, as NAME=S in (0, 1] (repeat it; a categories.json
    /// `"strength"` does the same): its pixels start from the render and are redrawn this
    /// strongly, the rest at --init-strength (else 1), as ComfyUI's DifferentialDiffusion.
    #[arg(long, value_parser = parse_named_strength, value_name = "NAME=S")]
    category_strength: Vec<(String, f64)>,
    /// The background's img2img strength, in (0, 1].
    #[arg(long)]
    background_strength: Option<f64>,
    /// Pixels over which the category prompts' masks and the strengths blend into each other
    /// (a Gaussian of standard deviation PX/2); 0 keeps the masks' edges.
    #[arg(long, default_value_t = 0, value_name = "PX")]
    region_feather: usize,
    /// Images per UNet pass (2 × batch rows with guidance); results do not depend on it.
    #[arg(long, default_value_t = 1)]
    batch: usize,
    /// This process's part, I/N (0-based): the scenes whose number is I mod N. Without it, a
    /// Slurm array task or a Kubernetes Indexed Job (with --shards) picks its part.
    #[arg(long)]
    shard: Option<String>,
    /// Free space to leave on the dataset's file system: before each image, the images left
    /// (at the size measured so far) must fit beside it, else the run stops, resumable.
    #[arg(long, default_value = "2G", value_parser = parse_size, value_name = "SIZE")]
    min_free: u64,
    /// Shards in a Kubernetes Indexed Job (its completions); the index is JOB_COMPLETION_INDEX.
    #[arg(long)]
    shards: Option<u64>,
    /// Finish a set that another vkdiff version began (its kernels may give other bytes); the
    /// version is recorded in dataset.json, and later runs of it need no flag.
    #[arg(long)]
    allow_version_change: bool,
    /// Make the images `vkdiff dataset audit` flagged (DIR/audit.json) again with new seeds, the
    /// other images kept: with any flag, or one of KINDS (`--regenerate-flagged=missing`). Give
    /// the flags the set was made with; the same command resumes. Audit again afterwards.
    #[arg(long, num_args = 0..=1, require_equals = true, default_missing_value = "all", value_delimiter = ',', value_name = "KINDS")]
    regenerate_flagged: Option<Vec<String>>,
}

#[derive(Subcommand, Debug)]
enum DatasetCommand {
    /// Join every image's annotations into DIR/annotations.json, once every shard is done.
    Merge {
        /// The dataset folder.
        dir: PathBuf,
        /// Merge a set that another vkdiff version began (recorded in dataset.json).
        #[arg(long)]
        allow_version_change: bool,
    },
    Export(crate::dataset_export_cmd::ExportArgs),
    Stats(crate::dataset_stats_cmd::StatsArgs),
    Preview(crate::dataset_preview_cmd::PreviewArgs),
    Audit(crate::dataset_audit_cmd::AuditArgs),
}

pub fn run(args: &DatasetArgs, env: &vkdiff_runtime::Environment) -> Result<()> {
    match &args.command {
        Some(DatasetCommand::Merge { dir, allow_version_change }) => {
            print_merged(dir, &merge(dir, versions(*allow_version_change))?);
            return Ok(());
        }
        Some(DatasetCommand::Export(export)) => return crate::dataset_export_cmd::run(export),
        Some(DatasetCommand::Stats(stats)) => return crate::dataset_stats_cmd::run(stats),
        Some(DatasetCommand::Preview(preview)) => return crate::dataset_preview_cmd::run(preview),
        Some(DatasetCommand::Audit(audit)) => return crate::dataset_audit_cmd::run(audit),
        None => {}
    }
    let out = args.out.as_deref().context("--out DIR is required")?;
    let shard = ShardRequest { shard: args.shard.clone(), shards: args.shards };
    let options = RunOptions {
        batch: args.batch,
        threads: args.scene.threads,
        min_free: args.min_free,
        versions: versions(args.allow_version_change),
        keep_text_encoders: false,
        regenerate: args.regenerate_flagged.as_deref().map(|kinds| match kinds {
            [all] if all == "all" => Vec::new(),
            kinds => kinds.to_vec(),
        }),
    };
    let mut job = DatasetJob::new(settings(args, env)?, out, shard, options, &|k| env.raw(k).map(String::from))?;
    if let Some(models) = &job.settings().models {
        for warning in recipe_warnings(models, &job.settings().sampling)? {
            eprintln!("{warning}");
        }
    }
    if let Some(line) = job.regeneration_line() {
        eprintln!("{line}");
    }
    for why in job.redo() {
        eprintln!("making again: {why}");
    }
    eprintln!("{}", job.plan_line());
    if job.todo() > 0 {
        // Ctrl-C or a scheduler's SIGTERM: the images in hand are written, then exit code 4.
        stop_on_signals();
        let ctx = job.needs_device().then(|| crate::open_device(&args.model.device, env)).transpose()?;
        let done = job.done() as usize;
        let total = done + job.todo() as usize;
        let total_images = job.settings().images() as f64;
        // The bar and the clock start once the models are loaded: the closing line's per-image
        // figure is the loop's.
        let mut bar = Progress::resuming("images", "image", done);
        let mut start = Instant::now();
        let mut made = done;
        let disk = job.disk();
        let mut estimated = done > 0;
        let report = job.run(ctx.as_ref(), &mut |event| match event {
            DatasetEvent::Note(line) => eprintln!("{line}"),
            DatasetEvent::Loaded(time) => {
                eprintln!("loaded in {:.1} s", time.as_secs_f64());
                bar = Progress::resuming("images", "image", done);
                start = Instant::now();
            }
            DatasetEvent::Progress(Event::Images { done, .. }) => {
                made = done as usize;
                // Printed once measured, then refined on the bar as images are written.
                let set_size = disk.per_image().map(|per| size((per * total_images) as u64));
                if let Some(set_size) = set_size.as_ref().filter(|_| !estimated) {
                    estimated = true;
                    eprintln!("estimated size of the whole set: {set_size} (from the first image)");
                }
                bar.show(made, total, &set_size.map_or(String::new(), |s| format!("  (set ≈ {s})")), true);
            }
            DatasetEvent::Progress(Event::Step { step, steps }) => {
                bar.show(made, total, &format!("  (step {step}/{steps})"), false)
            }
        })?;
        let mut closing = closing_line(&report, start.elapsed(), ctx.as_ref().map(|c| c.peak_bytes()));
        if let Some(bytes) = job.estimated_size() {
            closing += &format!("; the whole set: about {} on disk", size(bytes));
        }
        eprintln!("{closing}");
        if let Some(line) = ctx.as_ref().and_then(|c| c.tuning_summary()) {
            eprintln!("{line}");
        }
    }
    match job.finish()? {
        Finish::Merged(merged) => print_merged(out, &merged),
        Finish::ShardDone { recorded, total } => println!(
            "shard {} done; {recorded} of {total} images are made. Once every shard is: vkdiff dataset merge {}",
            job.shard_name(),
            out.display()
        ),
    }
    Ok(())
}

fn print_merged(dir: &Path, merged: &Merged) {
    println!(
        "wrote {}: {} images, {} annotations",
        dir.join("annotations.json").display(),
        merged.images,
        merged.annotations
    );
}

fn settings(args: &DatasetArgs, env: &vkdiff_runtime::Environment) -> Result<DatasetSettings> {
    let mut prompts = args.prompt.clone();
    if let Some(file) = &args.prompts {
        prompts.extend(read_prompts(file)?);
    }
    let mut ip_sets = Vec::new();
    if !args.ip_image.is_empty() {
        ip_sets.push(args.ip_image.clone());
    }
    ip_sets.extend(
        args.ip_set
            .iter()
            .map(|set| set.split(',').map(str::trim).filter(|p| !p.is_empty()).map(PathBuf::from).collect()),
    );
    let models = match (args.render_only, args.model.model_flag_given()) {
        (true, Some(flag)) => {
            return Err(vkdiff_args::Usage(format!(
                "{} makes the shaded renders the images: drop {}",
                dataset_flag("render_only"),
                dataset_flag(flag)
            ))
            .into())
        }
        (true, None) => None,
        (false, _) => Some(args.model.settings(env)?),
    };
    let crops =
        Crops { count: args.crops.crops, size: args.crops.crop_size, min_fraction: args.crops.crop_min_fraction };
    let source: Arc<dyn SceneSource> = match &args.scenes {
        Some(dir) => {
            eprintln!("reading the scenes in {}", dir.display());
            let scenes = RenderedScenes::open(dir, &args.category, args.far)?;
            for note in scenes.notes() {
                eprintln!("note: {note}");
            }
            Arc::new(scenes)
        }
        None => Arc::new(ProceduralBed::new(args.scene.config())?),
    };
    Ok(DatasetSettings::new(
        args.scene.seed,
        args.count,
        source,
        crops,
        args.model.control_depth(),
        models,
        prompts,
        args.sampling.negative_prompt.clone(),
        Sampling { strength: args.init_strength, ..args.sampling.sampling(0, 0) },
        ip_sets,
        args.wildcards.clone(),
    )?
    .with_controls(&args.controls, args.edge_depth_jump)?
    .with_regions(&RegionFlags {
        prompts: args.category_prompt.clone(),
        strengths: args.category_strength.clone(),
        background: args.background_strength,
        feather: args.region_feather,
    })?)
}

/// `NAME=TEXT`; the first `=` ends the name.
fn parse_named_text(text: &str) -> std::result::Result<(String, String), String> {
    match text.split_once('=') {
        Some((name, value)) if !name.trim().is_empty() => Ok((name.trim().to_string(), value.to_string())),
        _ => Err("expected NAME=TEXT, as apple=a shiny red apple".into()),
    }
}

/// `NAME=S`, S a number.
fn parse_named_strength(text: &str) -> std::result::Result<(String, f64), String> {
    let (name, value) = parse_named_text(text)?;
    let strength = value.trim().parse().map_err(|_| format!("{name}={value}: the strength is not a number"))?;
    Ok((name, strength))
}

/// A control's name, as `--controls` takes it.
fn parse_control(name: &str) -> std::result::Result<ControlKind, String> {
    ControlKind::parse(name).ok_or_else(|| {
        let kinds: Vec<&str> = ControlKind::ALL.iter().map(|k| k.name()).collect();
        format!("expected one of {}", kinds.join(", "))
    })
}

/// Per-stage seconds and peak device memory (None: a render-only set, which used no device).
fn closing_line(report: &Report, elapsed: Duration, peak: Option<u64>) -> String {
    let t = &report.times;
    let s = |d: Duration| format!("{:.1} s", d.as_secs_f64());
    let made = format!(
        "made {} images in {} ({:.2} s/image)",
        report.made,
        s(elapsed),
        elapsed.as_secs_f64() / report.made.max(1) as f64
    );
    let Some(peak) = peak else {
        return format!(
            "{made}: scene {} (on its own threads), write {}, waited for scenes {}",
            s(t.scene),
            s(t.write),
            s(t.waiting)
        );
    };
    format!(
        "{made}: scene {} (on its own threads), prompts/styles/recording {} (recorded {}×), guides {}, denoise {}, \
            VAE {}, write {} (on its own thread), waited for scenes {}; peak device memory {} MiB",
        s(t.scene),
        s(t.setup),
        report.recordings,
        s(t.guides),
        s(t.denoise()),
        s(t.vae),
        s(t.write),
        s(t.waiting),
        peak >> 20
    )
}

fn versions(allow_change: bool) -> VersionChange {
    if allow_change {
        VersionChange::Allow
    } else {
        VersionChange::Refuse
    }
}
