//! diffusers' `UNet2DConditionModel` (SDXL's), with its config, blocks, embeddings, the original
//! single-file layout, and the hooks ControlNet residuals and IP-Adapter tokens enter through.

pub(crate) mod config;
pub(crate) mod down_path;
mod embeddings;
mod load;
mod single_file;
pub(crate) mod unet_2d_blocks;
pub(crate) mod unet_2d_condition;

pub use config::{UNetConfig, SDXL_BASE_CONFIG};
pub use load::{
    check_swapped_unet, read_unet_config, single_file_unet_checkpoint, swapped_unet_checkpoint, swapped_unet_config,
    unet_checkpoint,
};
pub use single_file::unet_names;
pub use unet_2d_condition::{ControlResiduals, UNet, UNetInputs, UNetPass};
