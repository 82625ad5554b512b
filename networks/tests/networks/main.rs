//! The SDXL UNet against diffusers on tiny random models (tools/make_unet_fixtures.py), in both
//! checkpoint layouts and both precisions, with ControlNet residuals and IP-Adapter tokens.

mod conditioning;
mod controlnet;
mod controlnet_union;
mod errors;
mod forward;
mod fp8;
mod inception;
mod ip_adapter;
mod malformed;
mod random_single_file;
mod text_and_vae;
mod vae_tiling;
