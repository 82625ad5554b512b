//! `vkdiff gen`: text-to-image with an SDXL model, written as a PNG that carries its settings.

use crate::model_args::{ModelArgs, SamplingArgs};
use crate::progress::Progress;
use anyhow::{bail, Result};
use clap::Args;
use std::path::{Path, PathBuf};
use vkdiff_pipeline::files::{png_bytes, write_atomic_all};
use vkdiff_pipeline::{check_control_shape, GenSettings, PromptSyntax, Sdxl, TextToImage, WorkflowModels};
use vkdiff_runtime::Context;

/// Text-to-image with an SDXL model (diffusers folder or single .safetensors file).
#[derive(Args, Debug)]
pub struct GenArgs {
    #[command(flatten)]
    model: ModelArgs,
    #[arg(long)]
    prompt: String,
    /// torch.Generator("cpu").manual_seed(seed): diffusers gives the same noise for the same seed.
    #[arg(long, default_value_t = 0)]
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
    #[arg(long)]
    out: PathBuf,
    /// Replace --out (and --latents-out) when they exist.
    #[arg(long)]
    force: bool,
}

pub fn run(args: &GenArgs) -> Result<()> {
    for (flag, path) in
        std::iter::once(("--out", &args.out)).chain(args.latents_out.iter().map(|p| ("--latents-out", p)))
    {
        let parent = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        if !parent.is_dir() {
            bail!("{flag} {}: folder {} does not exist", path.display(), parent.display());
        }
        if path.exists() && !args.force {
            bail!("{flag} {} exists; give --force to replace it", path.display());
        }
    }
    if args.out.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() != Some("png") {
        bail!("--out {}: the image is written as PNG; give a .png path", args.out.display());
    }
    let mut settings = GenSettings {
        models: args.model.settings()?,
        job: TextToImage {
            prompt: args.prompt.clone(),
            negative_prompt: args.sampling.negative_prompt.clone(),
            seed: args.seed,
            sampling: args.sampling.sampling(0, 0),
        },
        depth: args.depth.clone(),
        ip_images: args.ip_image.clone(),
        init_image: args.init_image.clone(),
    };
    settings.models.check()?;
    let inputs = settings.read_inputs()?;
    // A depth map (else an init image) sets the size unless it is given: the image then lines up
    // with the depth; an init image keeps its size as diffusers' img2img does.
    let given = inputs.control.as_ref().filter(|_| args.depth.is_some()).or(inputs.init.as_ref());
    let (default_w, default_h) = given.map_or((1024, 1024), |c| (c.width, c.height));
    settings.job.sampling = args.sampling.sampling(args.width.unwrap_or(default_w), args.height.unwrap_or(default_h));
    settings.job.sampling.strength = args.init_image.as_ref().map(|_| args.strength.unwrap_or(0.3));
    let sampling = &settings.job.sampling;
    sampling.check()?;
    for prompt in std::iter::once(&settings.job.prompt).chain(&settings.job.negative_prompt) {
        sampling.prompt_syntax.check(prompt)?;
    }
    let multiple = Sdxl::probe_pixel_multiple(&settings.models.model)?;
    sampling.check_size(multiple)?;
    if let Some(control) = &inputs.control {
        check_control_shape(control, sampling.width, sampling.height, multiple)?;
    }

    let ctx = Context::new(args.model.device)?;
    eprintln!("device: {}", ctx.info().name);
    let start = std::time::Instant::now();
    let models = WorkflowModels::load(&ctx, &settings.models, &mut |line| eprintln!("{line}"))?;
    eprintln!("loaded in {:.1} s", start.elapsed().as_secs_f64());
    warn_cut_prompts(
        &models.sdxl,
        settings.job.sampling.prompt_syntax,
        [Some(&settings.job.prompt), settings.job.negative_prompt.as_ref()].into_iter().flatten(),
    );
    let progress = Progress::new("denoising", "step");
    let out = models
        .sdxl
        .text_to_image(&settings.job, &models.guides(&inputs), &mut |done, total| progress.update(done, total))?;
    let t = &out.timings;
    let steps: f64 = t.steps.iter().map(|d| d.as_secs_f64()).sum();
    eprintln!(
        "text encoding {:.2} s, {:.2} s/step over {} steps, VAE {:.2} s, peak device memory {} MiB",
        t.text_encoding.as_secs_f64(),
        steps / t.steps.len().max(1) as f64,
        t.steps.len(),
        t.vae.as_secs_f64(),
        ctx.peak_bytes() >> 20
    );
    let text = settings.png_text();
    let png = png_bytes(&out.image, &text)?;
    // The image and its latents appear together or not at all.
    let latents = args
        .latents_out
        .as_ref()
        .map(|_| vkdiff_formats::safetensors_f32_bytes(&[("latents", &out.latent_shape, &out.latents)], &text));
    let mut files = vec![(args.out.as_path(), png.as_slice())];
    files.extend(args.latents_out.as_deref().zip(latents.as_deref()));
    write_atomic_all(&files)?;
    eprintln!("wrote {}", args.out.display());
    Ok(())
}

/// Plain prompts past CLIP's 75 tokens lose their end, as in diffusers: say so.
pub fn warn_cut_prompts<'a>(sdxl: &Sdxl, syntax: PromptSyntax, prompts: impl Iterator<Item = &'a String>) {
    if syntax != PromptSyntax::Plain {
        return;
    }
    for prompt in prompts {
        let cut = sdxl.tokens_cut(prompt);
        if cut > 0 {
            eprintln!("warning: the last {cut} tokens of \"{prompt}\" are cut (CLIP reads 75); --prompt-syntax weighted reads any length");
        }
    }
}
