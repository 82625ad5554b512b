//! `vkdiff bench workflow`: the paper's denoising (SDXL + depth ControlNet + IP-Adapter with two
//! style images + two merged LoRAs) with full-size architectures and random weights, seconds per
//! step beside a plain text-to-image step of the same model measured in the same run. The VAE,
//! the same with or without the guides, is left out (`vkdiff bench gen` times it).

use crate::random_models::{gradient, style_images, RandomGuides};
use anyhow::Result;
use std::time::Instant;
use vkdiff_lora::LoraFile;
use vkdiff_pipeline::images::ClipPreprocess;
use vkdiff_pipeline::{ControlGuide, Guides, ImageGuide, Sdxl};
use vkdiff_runtime::Context;

#[derive(clap::Args)]
pub struct WorkflowArgs {
    #[command(flatten)]
    device: vkdiff_args::DeviceArgs,
    /// Image sizes in pixels (square).
    #[arg(long, value_delimiter = ',', default_values_t = [1024])]
    size: Vec<usize>,
    #[arg(long, default_value_t = 2)]
    steps: usize,
    #[arg(long, default_value_t = 32)]
    lora_rank: usize,
    #[arg(long, value_enum, default_value_t = vkdiff_args::Precision::F16)]
    precision: vkdiff_args::Precision,
}

pub fn run(args: &WorkflowArgs) -> Result<()> {
    let dtype = args.precision.dtype();
    let ctx = Context::new(&args.device.choice())?;
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
        let base = model
            .denoise(&job, &Guides::default(), &mut |done, total| eprintln!("{size}² base: step {done}/{total}"))?;
        let base_step = mean_step(&base.timings.steps);
        let refs: Vec<(&LoraFile, f32)> = loras.iter().map(|(f, s)| (f, *s)).collect();
        let merge = model.set_loras(&refs)?.map_or(0.0, |s| s.seconds);
        let depth = gradient(size, size, 3);
        let guides = Guides {
            control: Some(ControlGuide { net: &controlnet, image: &depth, scale: 0.5, start: 0.0, end: 1.0 }),
            image: Some(ImageGuide {
                adapter: &adapter,
                encoder: &encoder,
                preprocess: &preprocess,
                images: &styles,
                scale: &vkdiff_pipeline::IpScale::All(0.6),
            }),
            init: None,
        };
        let start = Instant::now();
        let out =
            model.denoise(&job, &guides, &mut |done, total| eprintln!("{size}² workflow: step {done}/{total}"))?;
        let total_s = start.elapsed().as_secs_f64();
        let t = &out.timings;
        let step = mean_step(&t.steps);
        println!(
            "{} | SDXL + depth ControlNet + IP-Adapter (ViT-H, 2 images) + 2 rank-{} LoRAs, {size}², {}: {step:.1} \
                s/step ({:.2}× a plain step of {base_step:.1} s measured in this run), prepare + record {:.1} s, text \
                {:.2} s, total without VAE {total_s:.1} s | load {load_s:.1} s, LoRA merge {merge:.1} s, peak {:.0} \
                MiB",
            ctx.info().name,
            args.lora_rank,
            crate::kernels::dtype_name(dtype),
            step / base_step,
            t.record.as_secs_f64(),
            t.text_encoding.as_secs_f64(),
            ctx.peak_bytes() as f64 / (1 << 20) as f64,
        );
    }
    Ok(())
}

fn mean_step(steps: &[std::time::Duration]) -> f64 {
    steps.iter().map(|d| d.as_secs_f64()).sum::<f64>() / steps.len().max(1) as f64
}
