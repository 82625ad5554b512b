//! What drives vkdiff's networks: the CLIP tokenizer, torch-compatible noise, the diffusers
//! schedulers, and text-to-image.

mod error;
mod prompt_encoding;
mod rng;
mod schedulers;
mod sdxl;
mod text_to_image;
mod tokenizer;

pub use error::{Error, Result};
pub use rng::TorchCpuRng;
pub use schedulers::{Sampler, SamplerKind, SchedulerConfig};
pub use sdxl::Sdxl;
pub use text_to_image::{Generated, RgbImage, TextToImage, Timings};
pub use tokenizer::ClipTokenizer;
