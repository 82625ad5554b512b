//! `vkdiff bench workflow`: the paper's denoising (SDXL + depth ControlNet + IP-Adapter with two
//! style images + two merged LoRAs) with full-size architectures and random weights, seconds per
//! step beside a plain text-to-image step of the same model measured in the same run. The VAE,
//! the same with or without the guides, is left out (`vkdiff bench gen` times it).

use anyhow::Result;
use std::time::Instant;
use vkdiff_lora::LoraFile;
use vkdiff_networks::{
    Checkpoint, ClipVisionConfig, ClipVisionModelWithProjection, ControlNetConfig, ControlNetModel, IpAdapter,
    SDXL_CONTROLNET_CONFIG,
};
use vkdiff_pipeline::images::ClipPreprocess;
use vkdiff_pipeline::{ControlGuide, Guides, ImageGuide, RgbImage, Sdxl};
use vkdiff_runtime::{Context, Dtype};

/// h94's `models/image_encoder` (OpenCLIP ViT-H/14 vision tower, 632 M parameters), the encoder of
/// ip-adapter_sdxl_vit-h.
const VIT_H_CONFIG: &str = r#"{"hidden_size": 1280, "intermediate_size": 5120, "num_hidden_layers": 32, "num_attention_heads": 16,
    "image_size": 224, "patch_size": 14, "projection_dim": 1024, "hidden_act": "gelu", "layer_norm_eps": 1e-5}"#;

#[derive(clap::Args)]
pub struct WorkflowArgs {
    /// Vulkan device index (see `vkdiff devices`).
    #[arg(long)]
    device: Option<usize>,
    /// Image sizes in pixels (square).
    #[arg(long, value_delimiter = ',', default_values_t = [1024])]
    size: Vec<usize>,
    #[arg(long, default_value_t = 2)]
    steps: usize,
    #[arg(long, default_value_t = 32)]
    lora_rank: usize,
    #[arg(long, value_enum, default_value_t = crate::model_args::Precision::F16)]
    precision: crate::model_args::Precision,
}

pub fn run(args: &WorkflowArgs) -> Result<()> {
    let dtype = args.precision.dtype();
    let ctx = Context::new(args.device)?;
    let start = Instant::now();
    let mut model = Sdxl::random_sdxl_base(&ctx, dtype)?;
    let RandomGuides { controlnet, encoder, adapter, loras } =
        RandomGuides::build(&ctx, &model, dtype, args.lora_rank)?;
    let load_s = start.elapsed().as_secs_f64();
    let preprocess = ClipPreprocess::square(encoder.config().image_size);
    let styles = style_images();
    for &size in &args.size {
        let job = super::gen::bench_job(size, args.steps);
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
            "{} | SDXL + depth ControlNet + IP-Adapter (ViT-H, 2 images) + 2 rank-{} LoRAs, {size}², {}: {step:.1} s/step ({:.2}× a plain step of {base_step:.1} s measured in this run), prepare + record {:.1} s, text {:.2} s, total without VAE {total_s:.1} s | load {load_s:.1} s, LoRA merge {merge:.1} s, peak {:.0} MiB",
            ctx.info().name,
            args.lora_rank,
            super::kernels::dtype_name(dtype),
            step / base_step,
            t.record.as_secs_f64(),
            t.text_encoding.as_secs_f64(),
            ctx.peak_bytes() as f64 / (1 << 20) as f64,
        );
    }
    Ok(())
}

/// The paper's guides with full-size architectures and random weights: a depth ControlNet, a
/// ViT-H image encoder with a plain SDXL IP-Adapter, and two rank-r LoRAs (strengths 0.8, 0.6).
pub(super) struct RandomGuides {
    pub controlnet: ControlNetModel,
    pub encoder: ClipVisionModelWithProjection,
    pub adapter: IpAdapter,
    pub loras: [(LoraFile, f32); 2],
}

impl RandomGuides {
    pub fn build(ctx: &Context, model: &Sdxl, dtype: Dtype, lora_rank: usize) -> Result<RandomGuides> {
        let control_config = ControlNetConfig::from_json(SDXL_CONTROLNET_CONFIG, "built-in ControlNet config")?;
        let controlnet =
            ControlNetModel::build(control_config, &Checkpoint::random(ctx, dtype, 6), model.unet_config())?;
        let vision_config: ClipVisionConfig = serde_json::from_str(VIT_H_CONFIG)?;
        let encoder = ClipVisionModelWithProjection::load(ctx, vision_config, &Checkpoint::random(ctx, dtype, 7))?;
        let adapter = IpAdapter::random_plain(ctx, model.unet(), encoder.config().projection_dim, 4, dtype)?;
        let loras = [(random_lora(model, lora_rank, 1)?, 0.8), (random_lora(model, lora_rank, 2)?, 0.6)];
        Ok(RandomGuides { controlnet, encoder, adapter, loras })
    }
}

/// Two style images of other sizes than the encoder's.
pub(super) fn style_images() -> [RgbImage; 2] {
    [gradient(300, 200, 1), gradient(180, 260, 2)]
}

fn mean_step(steps: &[std::time::Duration]) -> f64 {
    steps.iter().map(|d| d.as_secs_f64()).sum::<f64>() / steps.len().max(1) as f64
}

/// A kohya LoRA over every transformer linear of the model's UNet, as the bench writes them.
fn random_lora(model: &Sdxl, rank: usize, seed: u64) -> Result<LoraFile> {
    let path = std::env::temp_dir().join(format!("vkdiff-bench-workflow-{}-{seed}.safetensors", std::process::id()));
    super::lora::write_lora(&path, &super::lora::transformer_linears(model.unet()), rank, seed)?;
    let file = LoraFile::open(&path);
    std::fs::remove_file(&path)?;
    Ok(file?)
}

/// A smooth colour image, standing in for a style photo or a depth map.
fn gradient(width: usize, height: usize, seed: usize) -> RgbImage {
    let pixels = (0..height * width).flat_map(|i| {
        let (y, x) = (i / width, i % width);
        [(x * 255 / width) as u8, (y * 255 / height) as u8, ((x + y + 40 * seed) % 256) as u8]
    });
    RgbImage { width, height, pixels: pixels.collect() }
}
