//! transformers' CLIP towers: SDXL's two text encoders (CLIP ViT-L, OpenCLIP ViT-bigG) and the
//! vision encoder of IP-Adapter, in the diffusers and the original single-file layouts.

mod names;
mod text_config;
pub(crate) mod text_model;
mod vision_model;

pub(crate) use names::open_clip_names;
pub use names::TextEncoderSlot;
pub use text_config::{ClipTextConfig, SDXL_BIGG_CONFIG, SDXL_CLIP_L_CONFIG};
pub use text_model::{ClipTextModel, TextEncoding};
pub use vision_model::{ClipVisionConfig, ClipVisionModelWithProjection, ImageEncoding, ImageFeature};
