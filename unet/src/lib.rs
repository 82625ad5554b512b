//! vkdiff's networks as graphs of Vulkan runtime ops, built from diffusers configs, with weights
//! found by path in safetensors checkpoints of the diffusers or the original single-file layout.

mod attention;
mod checkpoint;
mod config;
mod embeddings;
mod error;
mod layout;
mod ldm_names;
mod nn;
mod resnet;
mod safetensors;
mod transformer_2d;
mod unet_2d_blocks;
mod unet_2d_condition;

pub use checkpoint::{Checkpoint, Weights};
pub use config::{UNetConfig, SDXL_BASE_CONFIG};
pub use error::{Error, Result};
pub use layout::{nchw_to_nhwc, nhwc_to_nchw};
pub use safetensors::{SafeTensors, SourceDtype};
pub use attention::{IpAdapterInput, IpLayer};
pub use nn::Linear;
pub use unet_2d_condition::{ControlResiduals, UNet, UNetInputs, UNetPass};
