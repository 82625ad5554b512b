//! What drives vkdiff's networks: the CLIP tokenizer, torch-compatible noise, the diffusers
//! schedulers, and text-to-image.

mod controlnet_guide;
pub mod dataset;
mod denoiser;
mod error;
pub mod files;
mod gen_settings;
pub mod images;
mod img2img;
mod ip_adapter_guide;
mod ip_scale;
mod prompt_encoding;
mod prompt_syntax;
mod prompt_weights;
mod rng;
mod sampling;
mod schedulers;
mod sdxl;
mod text_to_image;
mod tokenizer;
mod workflow_models;

pub use controlnet_guide::{check_control_settings, check_control_shape, ControlGuide, ControlNetUse};
pub use denoiser::{BatchOutput, Denoiser, IpAdapterUse, ItemInputs};
pub use error::{Error, Result};
pub use gen_settings::{
    control_depth_name, precision_name, ControlNetSettings, GenSettings, IpAdapterSettings, LoraSetting, ModelSettings,
    RNG,
};
pub use img2img::InitLatents;
pub use ip_adapter_guide::ImageGuide;
pub use ip_scale::{IpBlock, IpMode, IpScale};
pub use prompt_encoding::Conditioning;
pub use prompt_syntax::{parse_attention, PromptSyntax};
pub use rng::TorchCpuRng;
pub use sampling::{Sampling, SizeConditioning, TextToImage};
pub use schedulers::{Sampler, SamplerKind, SchedulerConfig};
pub use sdxl::Sdxl;
pub use text_to_image::{Denoised, Generated, Guides, Timings};
pub use tokenizer::ClipTokenizer;
pub use vkdiff_formats::RgbImage;
pub use workflow_models::{read_images, GuideInputs, StyleModels, WorkflowModels};
