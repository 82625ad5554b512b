//! `vkdiff gen`: text-to-image with an SDXL model, written as a PNG that carries its settings.

use anyhow::Result;
use clap::Args;
use std::path::PathBuf;
use vkdiff_args::Progress;
use vkdiff_args::{ModelArgs, SamplingArgs};
use vkdiff_pipeline::{recipe_warnings, GenEvent, GenJob, GenRequest, GenSettings, TextToImage};
use vkdiff_render::control::ControlKind;

/// Text-to-image with an SDXL model (diffusers folder or single .safetensors file).
#[derive(Args, Debug)]
pub struct GenArgs {
    #[command(flatten)]
    model: ModelArgs,
    /// The prompt (see --prompt-syntax for weights and prompts past 75 tokens); it may be a
    /// template, expanded from --seed: {wet|dry}, {3::wet|dry}, __soil__ (docs/dataset.md).
    #[arg(short, long)]
    prompt: String,
    /// The folder of the wildcard files a template names: __soil__ is a line of DIR/soil.txt.
    #[arg(long, value_name = "DIR")]
    wildcards: Option<PathBuf>,
    /// torch.Generator("cpu").manual_seed(seed): diffusers gives the same noise for the same seed.
    #[arg(short, long, default_value_t = 0)]
    seed: u64,
    #[command(flatten)]
    sampling: SamplingArgs,
    /// Image width [default: the --depth image's, else 1024].
    #[arg(long)]
    width: Option<usize>,
    /// Image height [default: the --depth image's, else 1024].
    #[arg(long)]
    height: Option<usize>,
    /// The ControlNet's input: a metric-depth EXR (channel Z, <layer>.Depth.Z, V or R), turned
    /// into an image as `vkdiff scene` writes control.png, or an image used as it is.
    #[arg(long, requires = "controlnet")]
    depth: Option<PathBuf>,
    /// The image of a control other than depth that a --controlnet sees, as KIND=FILE (edges,
    /// segmentation or normals, as `vkdiff dataset --controls` writes them); repeat it for each.
    #[arg(long, requires = "controlnet", value_parser = parse_control_image, value_name = "KIND=FILE")]
    control_image: Vec<(ControlKind, PathBuf)>,
    /// A style image for --ip-adapter; repeat it for several, whose tokens are joined as
    /// diffusers joins several images given to one adapter.
    #[arg(long, requires = "ip_adapter")]
    ip_image: Vec<PathBuf>,
    /// img2img: start from this image (resized to the output where its size differs) instead of
    /// noise, as diffusers' StableDiffusionXLImg2ImgPipeline (or its ControlNet twin with --depth).
    #[arg(long)]
    init_image: Option<PathBuf>,
    /// img2img: the share of the schedule run over the init image, (0, 1]; the last
    /// ⌊steps · strength⌋ steps run [default: 0.3, diffusers' SDXL img2img default].
    #[arg(long, requires = "init_image")]
    strength: Option<f64>,
    /// Also write the final latents (before VAE scaling), NCHW float32, tensor `latents`.
    #[arg(long)]
    latents_out: Option<PathBuf>,
    /// Output PNG.
    #[arg(short, long)]
    out: PathBuf,
    /// Replace --out (and --latents-out) when they exist.
    #[arg(long)]
    force: bool,
}

/// `KIND=FILE` for a control other than depth (which `--depth` gives).
fn parse_control_image(text: &str) -> std::result::Result<(ControlKind, PathBuf), String> {
    let (kind, file) = text.split_once('=').ok_or("expected KIND=FILE, as edges=edges.png")?;
    match ControlKind::parse(kind) {
        Some(ControlKind::Depth) => Err("the depth control is --depth FILE".into()),
        Some(kind) if !file.is_empty() => Ok((kind, file.into())),
        Some(_) => Err("expected KIND=FILE, as edges=edges.png".into()),
        None => Err(format!("{kind}: expected edges, segmentation or normals")),
    }
}

pub fn run(args: &GenArgs, env: &vkdiff_runtime::Environment) -> Result<()> {
    let settings = GenSettings {
        models: args.model.settings(env)?,
        job: TextToImage {
            prompt: args.prompt.clone(),
            negative_prompt: args.sampling.negative_prompt.clone(),
            seed: args.seed,
            sampling: args.sampling.sampling(0, 0),
        },
        depth: args.depth.clone(),
        control_images: args.control_image.clone(),
        ip_images: args.ip_image.clone(),
        init_image: args.init_image.clone(),
    };
    let job = GenJob::new(GenRequest {
        settings,
        width: args.width,
        height: args.height,
        strength: args.strength,
        out: args.out.clone(),
        latents_out: args.latents_out.clone(),
        replace: args.force,
        wildcards: args.wildcards.clone(),
    })?;
    for warning in recipe_warnings(&job.settings().models, &job.settings().job.sampling)? {
        eprintln!("{warning}");
    }
    let ctx = crate::open_device(&args.model.device, env)?;
    // The bar starts once the models are loaded, so its rate is the denoiser's.
    let mut progress = None;
    let t = job.run(&ctx, &mut |event| match event {
        GenEvent::Note(line) => eprintln!("{line}"),
        GenEvent::Loaded(time) => {
            eprintln!("loaded in {:.1} s", time.as_secs_f64());
            progress = Some(Progress::new("denoising", "step"));
        }
        GenEvent::Step { done, total } => {
            progress.get_or_insert_with(|| Progress::new("denoising", "step")).update(done, total);
            // The decode that follows can take minutes on a CPU device, with no bar of its own.
            if done == total {
                eprintln!("VAE: decoding the latents");
            }
        }
    })?;
    let steps: f64 = t.steps.iter().map(|d| d.as_secs_f64()).sum();
    eprintln!(
        "text encoding {:.2} s, {:.2} s/step over {} steps, VAE {:.2} s, peak device memory {} MiB",
        t.text_encoding.as_secs_f64(),
        steps / t.steps.len().max(1) as f64,
        t.steps.len(),
        t.vae.as_secs_f64(),
        ctx.peak_bytes() >> 20
    );
    if let Some(line) = ctx.tuning_summary() {
        eprintln!("{line}");
    }
    eprintln!("wrote {}", args.out.display());
    Ok(())
}
