//! What drives vkdiff's networks: the CLIP tokenizer, torch-compatible noise, the diffusers
//! schedulers, and text-to-image.

mod controlnet_guide;
mod error;
mod ip_adapter_guide;
pub mod images;
mod prompt_encoding;
mod rng;
mod schedulers;
mod sdxl;
mod text_to_image;
mod tokenizer;

pub use error::{Error, Result};
pub use ip_adapter_guide::ImageGuide;
pub use rng::TorchCpuRng;
pub use schedulers::{Sampler, SamplerKind, SchedulerConfig};
pub use sdxl::Sdxl;
pub use controlnet_guide::{check_control_settings, ControlGuide};
pub use text_to_image::{Denoised, Generated, Guides, RgbImage, TextToImage, Timings};
pub use tokenizer::ClipTokenizer;
