//! `vkdiff bench dataset`: the dataset loop with the paper's workflow (SDXL base + depth
//! ControlNet + IP-Adapter over two style images + two merged LoRAs, full-size architectures,
//! random weights) on a few scenes, seconds per image by stage. Beside it, in the same run, what
//! one `vkdiff gen` per image pays: the load and LoRA merge, and a single image with its guides
//! prepared and its passes recorded on its own.

use crate::random_models::{gradient_depth, style_images, RandomGuides};
use anyhow::Result;
use std::sync::Arc;
use std::time::{Duration, Instant};
use vkdiff_dataset::{
    generate, Crops, Dataset, DatasetSettings, DiskGuard, LabelControls, ProceduralBed, Report, RunOptions, Shard,
};
use vkdiff_lora::LoraFile;
use vkdiff_pipeline::images::{ClipPreprocess, ControlDepth};
use vkdiff_pipeline::{
    ControlNetSettings, GuideInputs, IpAdapterSettings, LoraSetting, ModelSettings, Sdxl, StyleModels, TextToImage,
    WorkflowModels,
};
use vkdiff_pipeline::{PromptTemplate, Wildcards};
use vkdiff_render::control::ControlKind;
use vkdiff_render::scene::SceneConfig;
use vkdiff_runtime::{Context, Dtype, Environment};

#[derive(clap::Args)]
pub struct DatasetArgs {
    #[command(flatten)]
    device: vkdiff_args::DeviceArgs,
    /// Image side (square crops of a frame 1920×1080 scaled by size/1024, three per scene).
    #[arg(long, default_value_t = 512)]
    size: usize,
    /// Scenes, three crops each.
    #[arg(long, default_value_t = 1)]
    scenes: u64,
    /// Denoising steps timed per image (--production-steps extrapolates).
    #[arg(long, default_value_t = 2)]
    steps: usize,
    /// Images per UNet pass.
    #[arg(long, default_value_t = 1)]
    batch: usize,
    /// Rank of the two random LoRAs merged.
    #[arg(long, default_value_t = 32)]
    lora_rank: usize,
    /// f16 (f32 arithmetic, matrix units where the GPU has them) or f32.
    #[arg(long, value_enum, default_value_t = vkdiff_args::Precision::F16)]
    precision: vkdiff_args::Precision,
    /// Steps per image in production, for the share of time that is not denoising.
    #[arg(long, default_value_t = 30)]
    production_steps: usize,
}

pub fn run(args: &DatasetArgs, env: &Environment) -> Result<()> {
    vkdiff_args::ensure_usage(args.size.is_multiple_of(32) && args.size >= 64, || {
        format!("--size {} must be a multiple of 32, at least 64", args.size)
    })?;
    vkdiff_args::ensure_usage(args.batch > 0, || "--batch must be at least 1".into())?;
    let dtype = args.precision.dtype();
    let ctx = args.device.open(env)?;
    let RandomWorkflow { mut models, load: load_once, .. } = random_workflow(&ctx, dtype, args.lora_rank)?;
    let dataset = paper_set(args.size, args.scenes, 3, args.steps, &models.settings);
    let styles = vec![style_images().to_vec()];
    // One image as `vkdiff gen` makes it: its own text encoding, guides and recording (first:
    // the set releases the text encoders once its prompts are encoded).
    let inputs = GuideInputs {
        controls: [(ControlKind::Depth, gradient_depth(args.size))].into(),
        style: style_images().to_vec(),
        init: None,
    };
    let job = TextToImage {
        prompt: dataset.prompts[0].clone(),
        negative_prompt: None,
        seed: 0,
        sampling: dataset.sampling.clone(),
    };
    let start = Instant::now();
    let single = models.sdxl.text_to_image(&job, &models.guides(&inputs), &mut |done, total| {
        eprintln!("single image: step {done}/{total}")
    })?;
    let single_wall = start.elapsed();
    let (report, wall) = make_set(&mut models, &dataset, &styles, args.batch, false)?;
    let images = report.made;
    let per = |d: Duration| d.as_secs_f64() / images.max(1) as f64;
    let t = &report.times;
    let step = per(t.denoise()) / args.steps as f64;
    // Steady state: what each further image costs besides its steps (the setup is paid once per
    // prompt, style set and batch shape, however many images follow).
    let overhead = per(wall - t.setup - t.denoise());
    let at = args.production_steps as f64;
    let single_steps: f64 = single.timings.steps.iter().map(Duration::as_secs_f64).sum();
    let gen_image = load_once.as_secs_f64() + single_wall.as_secs_f64() - single_steps + at * step;
    let dataset_image = overhead + at * step;
    // Each stage as timed: the scene and writing run on threads of their own, so the stages need
    // not add up to the wall time, and nothing is shown as "the rest" by subtraction.
    println!(
        "{} | dataset, SDXL + depth ControlNet + IP-Adapter (ViT-H, 2 images) + 2 rank-{} LoRAs, {}² crops, {} \
            images, {} steps, batch {}, {}: once {:.1} s (prompt, styles, recording); per image {:.1} s wall; each \
            stage as timed, per image (they need not add up to it): guides {:.2}, denoise {:.1} ({:.1} s/step), VAE \
            {:.2}; beside it per image: scene {:.2}, write {:.2}, waited {:.2} | at {} steps: {:.2} s/image not \
            denoising = {:.2} % | one gen per image at {} steps: load + LoRA merge {:.1} s + {:.1} s not denoising + \
            steps = {:.0} s/image, the dataset {:.0} s/image ({:.2}× faster, {:.0} s saved per image) | peak {} MiB",
        ctx.info().name,
        args.lora_rank,
        args.size,
        images,
        args.steps,
        args.batch,
        crate::kernels::dtype_name(dtype),
        t.setup.as_secs_f64(),
        per(wall - t.setup),
        per(t.guides),
        per(t.denoise()),
        step,
        per(t.vae),
        per(t.scene),
        per(t.write),
        per(t.waiting),
        args.production_steps,
        overhead,
        100.0 * overhead / dataset_image,
        args.production_steps,
        load_once.as_secs_f64(),
        single_wall.as_secs_f64() - single_steps,
        gen_image,
        dataset_image,
        gen_image / dataset_image,
        gen_image - dataset_image,
        ctx.peak_bytes() >> 20,
    );
    Ok(())
}

/// The paper's workflow with full-size architectures and random weights, its two LoRAs merged.
pub(crate) struct RandomWorkflow {
    pub models: WorkflowModels,
    /// The merged LoRAs' files and strengths.
    pub loras: Vec<(LoraFile, f32)>,
    /// Building the models and merging the LoRAs (what one `vkdiff gen` pays before its image).
    pub load: Duration,
}

/// Builds [`RandomWorkflow`].
pub(crate) fn random_workflow(ctx: &Context, dtype: Dtype, lora_rank: usize) -> Result<RandomWorkflow> {
    let start = Instant::now();
    let sdxl = Sdxl::random_sdxl_base(ctx, dtype)?;
    let RandomGuides { controlnet, encoder, adapter, loras } = RandomGuides::build(ctx, &sdxl, dtype, lora_rank)?;
    let load = start.elapsed();
    let settings = model_settings(dtype, &loras.each_ref().map(|(_, s)| *s));
    let preprocess = ClipPreprocess::square(encoder.config().image_size);
    let mut models = WorkflowModels {
        sdxl,
        controlnets: vec![(controlnet, Vec::new())],
        style: Some(StyleModels { adapter, encoder, preprocess }),
        settings,
    };
    let refs: Vec<(&LoraFile, f32)> = loras.iter().map(|(f, s)| (f, *s)).collect();
    let merge = models.sdxl.set_loras(&refs)?.map_or(Duration::ZERO, |s| Duration::from_secs_f64(s.seconds));
    eprintln!("models built in {:.1} s, LoRAs merged in {:.1} s", load.as_secs_f64(), merge.as_secs_f64());
    Ok(RandomWorkflow { models, loras: loras.into(), load: load + merge })
}

/// Makes `settings`' set in a fresh temporary folder, removed after: the loop's report and wall
/// time. `keep_text_encoders` lets further sets follow on the same models.
pub(crate) fn make_set(
    models: &mut WorkflowModels,
    settings: &DatasetSettings,
    styles: &[Vec<vkdiff_pipeline::RgbImage>],
    batch: usize,
    keep_text_encoders: bool,
) -> Result<(Report, Duration)> {
    static SETS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let n = SETS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("vkdiff-bench-dataset-{}-{n}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let folder = Dataset::open(&dir, settings, Default::default())?;
    let pending = folder.pending(Shard::ALL)?;
    let start = Instant::now();
    let report = generate(
        &folder,
        &DiskGuard::new(&folder, 0, 0, 0),
        settings,
        models,
        styles,
        pending,
        &RunOptions {
            batch,
            threads: 0,
            min_free: 0,
            versions: Default::default(),
            keep_text_encoders,
            regenerate: None,
        },
        &mut |event| {
            if let vkdiff_dataset::Progress::Images { done, total } = event {
                eprintln!("{done}/{total} images");
            }
        },
    );
    let wall = start.elapsed();
    std::fs::remove_dir_all(&dir)?;
    Ok((report?, wall))
}

/// The paths only name the random models in the images' metadata.
pub(crate) fn model_settings(precision: Dtype, lora_strengths: &[f32]) -> ModelSettings {
    ModelSettings {
        model: "random-sdxl-base".into(),
        vae: None,
        unet: None,
        precision,
        controlnets: vec![ControlNetSettings {
            model: "random-controlnet-depth".into(),
            controls: vec![ControlKind::Depth],
            depth_mode: ControlDepth::Inverse,
            scale: 0.5,
            start: 0.0,
            end: 1.0,
        }],
        ip_adapter: Some(IpAdapterSettings {
            adapter: "random-ip-adapter".into(),
            encoder: "random-vit-h".into(),
            scale: vkdiff_pipeline::IpScale::All(0.6),
        }),
        loras: lora_strengths
            .iter()
            .enumerate()
            .map(|(k, s)| LoraSetting { path: format!("random-lora-{k}").into(), strength: *s })
            .collect(),
        vae_tiling: Default::default(),
    }
}

/// The paper's prompt.
const PROMPT: &str = "white button mushrooms on dark black soil compost mycelium";

/// The paper's set in small: `scenes` frames of 1920×1080 scaled by size/1024, `crops` crops each.
pub(crate) fn paper_set(
    size: usize,
    scenes: u64,
    crops: usize,
    steps: usize,
    models: &ModelSettings,
) -> DatasetSettings {
    let scale = |v: usize| (v * size / 1024) as u32;
    let sampling = crate::gen::bench_sampling(size, steps);
    DatasetSettings {
        seed: 0,
        count: scenes,
        source: Arc::new(
            ProceduralBed::new(SceneConfig { width: scale(1920), height: scale(1080), ..SceneConfig::default() })
                .expect("the bench's scene settings are valid"),
        ),
        crops: Crops { count: crops, size: size as u32, min_fraction: 0.1 },
        control_depth: ControlDepth::Inverse,
        controls: LabelControls::default(),
        regions: Default::default(),
        models: Some(models.clone()),
        prompts: vec![PROMPT.into()],
        user_prompts: 1,
        templates: vec![PromptTemplate::parse(PROMPT).expect("a plain prompt")],
        wildcards: Wildcards::default(),
        negative_prompt: None,
        sampling,
        ip_sets: match models.ip_adapter {
            Some(_) => vec![vec!["style-1.png".into(), "style-2.png".into()]],
            None => Vec::new(),
        },
    }
}
