//! The SDXL UNet against diffusers on tiny random models (tools/make_unet_fixtures.py), in both
//! checkpoint layouts and both precisions, with ControlNet residuals and IP-Adapter tokens.

#[path = "../kernels/common.rs"]
#[allow(dead_code)]
mod common;

mod controlnet;
mod errors;
mod forward;
mod inception;
mod ip_adapter;
mod malformed;
mod text_and_vae;

use std::path::PathBuf;

pub fn fixture(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/unet").join(path)
}
