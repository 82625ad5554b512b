//! vkdiff's networks as graphs of Vulkan runtime ops, built from their diffusers/transformers
//! configs: SDXL's UNet, ControlNet, IP-Adapter, the CLIP text and vision encoders, the VAE, and
//! FID's InceptionV3. Weights are found by diffusers name in safetensors checkpoints of the
//! diffusers or the original single-file layout.

pub mod clip;
pub mod controlnet;
mod error;
pub mod inception;
pub mod ip_adapter;
mod layers;
mod random_single_file;
pub mod unet;
pub mod vae;
pub mod weights;

pub use clip::{
    ClipTextConfig, ClipTextModel, ClipVisionConfig, ClipVisionModelWithProjection, ImageEncoding, ImageFeature,
    TextEncoderSlot, TextEncoding, SDXL_BIGG_CONFIG, SDXL_CLIP_L_CONFIG,
};
pub use controlnet::{
    ControlNetConfig, ControlNetInputs, ControlNetModel, ControlNetPass, UnionCondition, SDXL_CONTROLNET_CONFIG,
};
pub use error::{Error, Result};
pub use inception::{InceptionV3, RandomInception, RgbPixels, TensorSource, INCEPTION_FEATURES, INCEPTION_SIZE};
pub use ip_adapter::{IpAdapter, IpAdapterKind};
pub use layers::attention::{CrossAttention, IpAdapterInput, IpLayer};
pub use layers::nn::Linear;
pub use layers::{nchw_to_nhwc, nhwc_to_nchw};
pub use random_single_file::{write_random_single_file, SdxlConfigs, RANDOM_SEEDS};
pub use unet::{
    check_swapped_unet, read_unet_config, single_file_unet_checkpoint, swapped_unet_checkpoint, swapped_unet_config,
    unet_checkpoint, unet_names, ControlResiduals, UNet, UNetConfig, UNetInputs, UNetPass, SDXL_BASE_CONFIG,
};
pub use vae::{AutoencoderKl, VaeConfig, VaeTiling, SDXL_VAE_CONFIG};
pub use weights::{Checkpoint, Inner, OriginalNames, ParamLayout, Parameter, Parameters, StoredAs, Weights};
