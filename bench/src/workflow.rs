//! `vkdiff bench workflow`: the paper's denoising (SDXL + depth ControlNet + IP-Adapter with two
//! style images + two merged LoRAs) with full-size architectures and random weights, seconds per
//! step beside a plain text-to-image step of the same model measured in the same run, and the
//! workflow's peak memory. The VAE, the same with or without the guides, runs only with
//! `--decode` (`vkdiff bench gen` times it), planned as `gen` plans it.

use crate::random_models::{gradient, style_images, RandomGuides};
use anyhow::Result;
use std::time::Instant;
use vkdiff_lora::LoraFile;
use vkdiff_pipeline::images::ClipPreprocess;
use vkdiff_pipeline::{ControlGuide, ControlNetUse, Denoised, Guides, ImageGuide, Sdxl, VaeTilingSetting};
use vkdiff_runtime::{Context, Environment};

#[derive(clap::Args)]
pub struct WorkflowArgs {
    #[command(flatten)]
    device: vkdiff_args::DeviceArgs,
    /// Image sizes in pixels (square).
    #[arg(long, value_delimiter = ',', default_values_t = [1024])]
    size: Vec<usize>,
    /// Denoising steps timed.
    #[arg(long, default_value_t = 2)]
    steps: usize,
    /// Rank of the two random LoRAs merged.
    #[arg(long, default_value_t = 32)]
    lora_rank: usize,
    /// f16 (f32 arithmetic, matrix units where the GPU has them) or f32.
    #[arg(long, value_enum, default_value_t = vkdiff_args::Precision::F16)]
    precision: vkdiff_args::Precision,
    /// Leaves out the plain text-to-image step (and the ratio to it): for memory runs.
    #[arg(long)]
    no_base: bool,
    /// Also decodes the workflow's latents, whole or in tiles as the memory plan decides.
    #[arg(long)]
    decode: bool,
}

pub fn run(args: &WorkflowArgs, env: &Environment) -> Result<()> {
    let dtype = args.precision.dtype();
    let ctx = args.device.open(env)?;
    let start = Instant::now();
    let mut model = Sdxl::random_sdxl_base(&ctx, dtype)?;
    let RandomGuides { controlnet, encoder, adapter, loras } =
        RandomGuides::build(&ctx, &model, dtype, args.lora_rank)?;
    let load_s = start.elapsed().as_secs_f64();
    let preprocess = ClipPreprocess::square(encoder.config().image_size);
    let styles = style_images();
    for &size in &args.size {
        let job = crate::gen::bench_job(size, args.steps);
        model.set_loras(&[])?;
        let base_step = if args.no_base {
            f64::NAN
        } else {
            let base = model
                .denoise(&job, &Guides::default(), &mut |done, total| eprintln!("{size}² base: step {done}/{total}"))?;
            mean_step(&base.timings.steps)
        };
        let refs: Vec<(&LoraFile, f32)> = loras.iter().map(|(f, s)| (f, *s)).collect();
        let merge = model.set_loras(&refs)?.map_or(0.0, |s| s.seconds);
        let depth = gradient(size, size, 3);
        let guides = Guides {
            control: vec![ControlGuide {
                use_: ControlNetUse { net: &controlnet, control_types: &[], scale: 0.5, start: 0.0, end: 1.0 },
                images: vec![&depth],
            }],
            image: Some(ImageGuide {
                adapter: &adapter,
                encoder: &encoder,
                preprocess: &preprocess,
                images: &styles,
                scale: &vkdiff_pipeline::IpScale::All(0.6),
            }),
            ..Default::default()
        };
        ctx.reset_peak();
        let start = Instant::now();
        let out =
            model.denoise(&job, &guides, &mut |done, total| eprintln!("{size}² workflow: step {done}/{total}"))?;
        let total_s = start.elapsed().as_secs_f64();
        let denoise_peak = ctx.peak_bytes();
        let decode = if args.decode { decode(&ctx, &mut model, &out, size)? } else { "no VAE decode".to_string() };
        let t = &out.timings;
        let step = mean_step(&t.steps);
        println!(
            "{} | SDXL + depth ControlNet + IP-Adapter (ViT-H, 2 images) + 2 rank-{} LoRAs, {size}², {}: {step:.1} \
                s/step ({:.2}× a plain step of {base_step:.1} s measured in this run), prepare + record {:.1} s, text \
                {:.2} s, total without VAE {total_s:.1} s | load {load_s:.1} s, LoRA merge {merge:.1} s | device \
                memory peak {} denoising, {decode}; host memory {}",
            ctx.info().name,
            args.lora_rank,
            crate::kernels::dtype_name(dtype),
            step / base_step,
            t.record.as_secs_f64(),
            t.text_encoding.as_secs_f64(),
            mib(denoise_peak),
            mib(ctx.host_bytes()),
        );
    }
    Ok(())
}

/// Decodes the workflow's latents as `gen` does (planned against the memory left) and says how,
/// in how long, and at what device memory peak.
fn decode(ctx: &Context, model: &mut Sdxl, out: &Denoised, size: usize) -> Result<String> {
    ctx.reset_peak();
    let plan = model.plan_vae(VaeTilingSetting::Auto, 1, size, size)?;
    let start = Instant::now();
    model.decode(&out.latents, out.latent_shape)?;
    let how = plan.tiling.map_or("whole".to_string(), |t| format!("in {}-px tiles", t.tile));
    Ok(format!("{} decoding {how} ({:.1} s)", mib(ctx.peak_bytes()), start.elapsed().as_secs_f64()))
}

fn mib(bytes: u64) -> String {
    format!("{} MiB", bytes.div_ceil(1 << 20))
}

fn mean_step(steps: &[std::time::Duration]) -> f64 {
    steps.iter().map(|d| d.as_secs_f64()).sum::<f64>() / steps.len().max(1) as f64
}
