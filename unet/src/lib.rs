//! vkdiff's networks (SDXL UNet, CLIP text encoders, VAE) as graphs of Vulkan runtime ops, built from diffusers configs, with weights
//! found by path in safetensors checkpoints of the diffusers or the original single-file layout.

mod attention;
mod autoencoder_kl;
mod biased_attention;
mod clip;
mod clip_vision;
mod clip_names;
mod checkpoint;
mod config;
mod controlnet;
mod controlnet_config;
mod down_path;
mod embeddings;
mod error;
mod layout;
mod ip_adapter;
mod ldm_names;
mod nn;
mod parameters;
mod resampler;
mod resnet;
mod safetensors;
mod transformer_2d;
mod unet_2d_blocks;
mod unet_2d_condition;
mod vae_names;

pub use autoencoder_kl::{AutoencoderKl, VaeConfig, SDXL_VAE_CONFIG};
pub use checkpoint::{Checkpoint, Weights};
pub use clip::{ClipTextConfig, ClipTextModel, TextEncoding, SDXL_BIGG_CONFIG, SDXL_CLIP_L_CONFIG};
pub use clip_names::TextEncoderSlot;
pub use clip_vision::{ClipVisionConfig, ClipVisionModelWithProjection, ImageEncoding, ImageFeature};
pub use config::{UNetConfig, SDXL_BASE_CONFIG};
pub use controlnet::{ControlNetInputs, ControlNetModel, ControlNetPass};
pub use controlnet_config::{ControlNetConfig, SDXL_CONTROLNET_CONFIG};
pub use error::{Error, Result};
pub use ip_adapter::{IpAdapter, IpAdapterKind};
pub use ldm_names::{OriginalNames, StoredAs};
pub use layout::{nchw_to_nhwc, nhwc_to_nchw};
pub use safetensors::{f32_file_bytes as safetensors_f32_bytes, write_f32 as write_safetensors_f32, SafeTensors, SourceDtype};
pub use attention::{IpAdapterInput, IpLayer};
pub use transformer_2d::CrossAttention;
pub use nn::Linear;
pub use parameters::{ParamLayout, Parameter, Parameters};
pub use unet_2d_condition::{ControlResiduals, UNet, UNetInputs, UNetPass};
