//! diffusers' `AutoencoderKL`: the VAE's encoder and decoder, in the diffusers and the original
//! single-file layouts.

mod autoencoder_kl;
mod config;
mod names;
mod tiled_decode;

pub use autoencoder_kl::AutoencoderKl;
pub use config::{VaeConfig, SDXL_VAE_CONFIG};
pub(crate) use names::vae_names;
pub use tiled_decode::VaeTiling;
