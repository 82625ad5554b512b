//! `vkdiff gen`: text-to-image with an SDXL model, written as a PNG that carries its settings.

use crate::gen_guides::GuideArgs;
use crate::progress::Progress;
use anyhow::{bail, Context as _, Result};
use clap::{Args, ValueEnum};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use vkdiff_pipeline::{Generated, SamplerKind, Sdxl, TextToImage};
use vkdiff_runtime::{Context, Dtype};

#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum Precision {
    /// f16 storage, f32 arithmetic (the VAE stays f32 where it would overflow).
    F16,
    F32,
}

#[derive(Clone, Copy, Debug, ValueEnum, PartialEq)]
enum Schedule {
    /// The model's scheduler_config.json as it is.
    Default,
    /// Karras et al. noise levels (euler, dpmpp_2m).
    Karras,
}

/// Text-to-image with an SDXL model (diffusers folder or single .safetensors file).
#[derive(Args, Debug)]
pub struct GenArgs {
    /// SDXL model: a diffusers folder or an original single-file checkpoint.
    #[arg(long)]
    model: PathBuf,
    #[arg(long)]
    prompt: String,
    /// Without it, the negative conditioning is zeros (diffusers' SDXL default).
    #[arg(long)]
    negative_prompt: Option<String>,
    /// torch.Generator("cpu").manual_seed(seed): diffusers gives the same noise for the same seed.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    #[arg(long, default_value_t = 30)]
    steps: usize,
    /// Classifier-free guidance scale; 1 or less runs without the negative pass.
    #[arg(long, default_value_t = 5.0, allow_negative_numbers = true)]
    cfg: f32,
    /// euler, euler_a, dpmpp_2m or ddim.
    #[arg(long, default_value = "euler")]
    sampler: SamplerKind,
    #[arg(long, value_enum, default_value_t = Schedule::Default)]
    scheduler: Schedule,
    #[arg(long, default_value_t = 1024)]
    width: usize,
    #[arg(long, default_value_t = 1024)]
    height: usize,
    #[arg(long, value_enum, default_value_t = Precision::F16)]
    precision: Precision,
    /// Noise generator: torch-cpu reproduces torch.randn on a CPU generator bit for bit.
    #[arg(long, default_value = "torch-cpu", value_parser = ["torch-cpu"])]
    rng: String,
    /// Also write the final latents (before VAE scaling), NCHW float32, tensor `latents`.
    #[arg(long)]
    latents_out: Option<PathBuf>,
    /// Vulkan device index (see `vkdiff devices`).
    #[arg(long)]
    device: Option<usize>,
    /// Output PNG.
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    guides: GuideArgs,
}

pub fn run(args: &GenArgs) -> Result<()> {
    for (flag, path) in std::iter::once(("--out", &args.out)).chain(args.latents_out.iter().map(|p| ("--latents-out", p))) {
        let parent = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        if !parent.is_dir() {
            bail!("{flag} {}: folder {} does not exist", path.display(), parent.display());
        }
    }
    if args.out.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() != Some("png") {
        bail!("--out {}: the image is written as PNG; give a .png path", args.out.display());
    }
    args.guides.check()?;
    let dtype = match args.precision {
        Precision::F16 => Dtype::F16,
        Precision::F32 => Dtype::F32,
    };
    let job = TextToImage {
        prompt: args.prompt.clone(),
        negative_prompt: args.negative_prompt.clone(),
        seed: args.seed,
        steps: args.steps,
        guidance_scale: args.cfg,
        sampler: args.sampler,
        karras: args.scheduler == Schedule::Karras,
        width: args.width,
        height: args.height,
    };
    let ctx = Context::new(args.device)?;
    eprintln!("device: {}", ctx.info().name);
    let start = std::time::Instant::now();
    let mut model = Sdxl::load(&ctx, &args.model, dtype, &mut |part| eprintln!("loading {part}"))?;
    let loaded = args.guides.load(&ctx, &model)?;
    loaded.merge_loras(&mut model)?;
    eprintln!("loaded in {:.1} s", start.elapsed().as_secs_f64());
    let guides = loaded.guides(&args.guides);
    let progress = Progress::new("denoising", "step");
    let out = model.text_to_image(&job, &guides, &mut |done, total| progress.update(done, total))?;
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
    let settings = settings(args);
    if let Some(path) = &args.latents_out {
        vkdiff_unet::write_safetensors_f32(path, &[("latents", &out.latent_shape, &out.latents)], &settings)?;
    }
    write_png(&args.out, &out, &settings)?;
    eprintln!("wrote {}", args.out.display());
    Ok(())
}

/// The settings as PNG text chunks and safetensors metadata: `parameters` in the A1111 form
/// that image browsers parse, plus every flag under its own key.
fn settings(a: &GenArgs) -> BTreeMap<String, String> {
    let negative = a.negative_prompt.as_deref().map(|n| format!("\nNegative prompt: {n}")).unwrap_or_default();
    let schedule = if a.scheduler == Schedule::Karras { " Karras" } else { "" };
    let parameters = format!(
        "{}{negative}\nSteps: {}, Sampler: {}{schedule}, CFG scale: {}, Seed: {}, Size: {}x{}, Model: {}, RNG: {}, Precision: {:?}{}",
        a.prompt,
        a.steps,
        a.sampler,
        a.cfg,
        a.seed,
        a.width,
        a.height,
        a.model.display(),
        a.rng,
        a.precision,
        a.guides.summary()
    );
    let mut m = BTreeMap::from([
        ("parameters".to_string(), parameters),
        ("prompt".into(), a.prompt.clone()),
        ("seed".into(), a.seed.to_string()),
        ("steps".into(), a.steps.to_string()),
        ("cfg".into(), a.cfg.to_string()),
        ("sampler".into(), a.sampler.to_string()),
        ("scheduler".into(), format!("{:?}", a.scheduler).to_lowercase()),
        ("width".into(), a.width.to_string()),
        ("height".into(), a.height.to_string()),
        ("precision".into(), format!("{:?}", a.precision).to_lowercase()),
        ("rng".into(), a.rng.clone()),
        ("model".into(), a.model.display().to_string()),
        ("software".into(), format!("vkdiff {}", env!("CARGO_PKG_VERSION"))),
    ]);
    if let Some(n) = &a.negative_prompt {
        m.insert("negative_prompt".into(), n.clone());
    }
    a.guides.settings(&mut m);
    m
}

/// 8-bit RGB PNG with international text chunks (prompts may be any language), written to a
/// temporary file and renamed, so an interrupted run leaves no half image.
fn write_png(path: &Path, out: &Generated, text: &BTreeMap<String, String>) -> Result<()> {
    let img = &out.image;
    let mut bytes = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut bytes, img.width as u32, img.height as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        for (k, v) in text {
            enc.add_itxt_chunk(k.clone(), v.clone())?;
        }
        let mut w = enc.write_header()?;
        w.write_image_data(&img.pixels)?;
    }
    let tmp = path.with_extension("png.partial");
    std::fs::write(&tmp, &bytes).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}
