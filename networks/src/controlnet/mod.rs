//! diffusers' `ControlNetModel`: a UNet's down path and mid block whose outputs become residuals
//! of the UNet, from a diffusers folder or an original (cldm) single file; ControlNet-Union's
//! extras in `union`.

mod config;
mod controlnet_model;
mod union;

pub use config::{ControlNetConfig, SDXL_CONTROLNET_CONFIG};
pub use controlnet_model::{ControlNetInputs, ControlNetModel, ControlNetPass};
pub use union::UnionCondition;
