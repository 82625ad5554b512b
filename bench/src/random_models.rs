//! The full-size networks the benchmarks run, with random weights: the paper's guides (a depth
//! ControlNet, a ViT-H image encoder with a plain SDXL IP-Adapter, two LoRAs) beside
//! `Sdxl::random_sdxl_base`, and the images that stand in for style photos and depth maps.
//! Weights come from `Checkpoint::random` (networks) and, for FID, `RandomInception`.

use anyhow::Result;
use vkdiff_lora::LoraFile;
use vkdiff_networks::{
    Checkpoint, ClipVisionConfig, ClipVisionModelWithProjection, ControlNetConfig, ControlNetModel, IpAdapter,
    SDXL_CONTROLNET_CONFIG,
};
use vkdiff_pipeline::{RgbImage, Sdxl};
use vkdiff_runtime::{Context, Dtype};

/// h94's `models/image_encoder` (OpenCLIP ViT-H/14 vision tower, 632 M parameters), the encoder of
/// ip-adapter_sdxl_vit-h.
const VIT_H_CONFIG: &str = r#"{"hidden_size": 1280, "intermediate_size": 5120, "num_hidden_layers": 32,
    "num_attention_heads": 16, "image_size": 224, "patch_size": 14, "projection_dim": 1024, "hidden_act": "gelu",
    "layer_norm_eps": 1e-5}"#;

/// The paper's guides with full-size architectures and random weights: a depth ControlNet, a
/// ViT-H image encoder with a plain SDXL IP-Adapter, and two rank-r LoRAs (strengths 0.8, 0.6).
pub struct RandomGuides {
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
pub fn style_images() -> [RgbImage; 2] {
    [gradient(300, 200, 1), gradient(180, 260, 2)]
}

/// A kohya LoRA over every transformer linear of the model's UNet, as the bench writes them.
fn random_lora(model: &Sdxl, rank: usize, seed: u64) -> Result<LoraFile> {
    let path = std::env::temp_dir().join(format!("vkdiff-bench-workflow-{}-{seed}.safetensors", std::process::id()));
    crate::lora::write_lora(&path, &crate::lora::transformer_linears(model.unet()), rank, seed)?;
    let file = LoraFile::open(&path);
    std::fs::remove_file(&path)?;
    Ok(file?)
}

/// A smooth colour image, standing in for a style photo or a depth map.
pub fn gradient(width: usize, height: usize, seed: usize) -> RgbImage {
    let pixels = (0..height * width).flat_map(|i| {
        let (y, x) = (i / width, i % width);
        [(x * 255 / width) as u8, (y * 255 / height) as u8, ((x + y + 40 * seed) % 256) as u8]
    });
    RgbImage { width, height, pixels: pixels.collect() }
}

/// A depth-like control image: brightness rising from left to right.
pub fn gradient_depth(size: usize) -> RgbImage {
    let pixels = (0..size * size).flat_map(|i| [((i % size) * 255 / size) as u8; 3]).collect();
    RgbImage { width: size, height: size, pixels }
}
