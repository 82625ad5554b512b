//! The file formats vkdiff reads and writes, below the networks and the metrics that use them:
//! safetensors (memory-mapped), PyTorch `.pth` files (a state dict, read without running pickled
//! code), and PNG/JPEG images decoded as `PIL.Image.open(path).convert("RGB")` decodes them; and
//! files written atomically (whole or not at all).

pub mod atomic;
mod error;
mod float8;
pub mod image;
mod safetensors;
mod stored_zip;
mod torch_pickle;
mod torch_pth;

pub use error::{Error, Result};
pub use image::RgbImage;
pub use safetensors::{
    decode, f32_file_bytes as safetensors_f32_bytes, write_f16_streamed as write_safetensors_f16_streamed,
    write_f32 as write_safetensors_f32, Entry, SafeTensors, SourceDtype,
};
pub use torch_pth::TorchPth;
