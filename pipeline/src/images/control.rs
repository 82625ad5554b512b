//! The ControlNet conditioning image as diffusers' SDXL ControlNet pipeline prepares a PIL
//! image: `VaeImageProcessor(do_convert_rgb=True, do_normalize=False).preprocess(image, h, w)`.

use super::resample::{resize_pil, Filter};
use crate::RgbImage;

/// diffusers rounds the requested size down to a multiple of the VAE scale factor (8 for SDXL)
/// even when it is given explicitly.
pub const VAE_SCALE_FACTOR: usize = 8;

/// (height, width) the control image is resized to for a `height`×`width` request.
pub fn control_size(height: usize, width: usize) -> (usize, usize) {
    (height - height % VAE_SCALE_FACTOR, width - width % VAE_SCALE_FACTOR)
}

/// NCHW [1, 3, H, W] float32 in 0..1 (u8 / 255 in float32): Lanczos resize when the size
/// differs, no normalisation to -1..1. Returns the values and the shape.
pub fn control_tensor(image: &RgbImage, width: usize, height: usize) -> (Vec<f32>, [usize; 4]) {
    let (h, w) = control_size(height, width);
    let resized;
    let img = if (image.width, image.height) != (w, h) {
        resized = resize_pil(image, w, h, Filter::Lanczos);
        &resized
    } else {
        image
    };
    let mut out = vec![0f32; 3 * h * w];
    for (i, px) in img.pixels.chunks_exact(3).enumerate() {
        for c in 0..3 {
            out[c * h * w + i] = px[c] as f32 / 255.0;
        }
    }
    (out, [1, 3, h, w])
}
