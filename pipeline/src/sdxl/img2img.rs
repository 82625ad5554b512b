//! img2img's start as diffusers' `StableDiffusionXLImg2ImgPipeline` makes it: the init image
//! resized to the output (Pillow's Lanczos, only where the sizes differ), mapped to [-1, 1] and
//! encoded by the VAE; the denoiser then samples its latent distribution and noises the sample
//! to the first step's level with the image's own generator.

use crate::error::Result;
use crate::images::{resize_pil, Filter};
use crate::sdxl::Sdxl;
use crate::RgbImage;
use vkdiff_networks::nhwc_to_nchw;

/// The VAE encoder's latent distribution of an init image, NCHW [1, C, h, w], before the VAE's
/// scaling factor.
pub struct InitLatents {
    pub mean: Vec<f32>,
    pub std: Vec<f32>,
}

impl Sdxl {
    /// Encodes `image` as the init image of a `width`×`height` generation.
    pub fn encode_init(&self, image: &RgbImage, width: usize, height: usize) -> Result<InitLatents> {
        let resized;
        let image = if (image.width, image.height) == (width, height) {
            image
        } else {
            resized = resize_pil(image, width, height, Filter::Lanczos);
            &resized
        };
        // VaeImageProcessor: u8 / 255 in float32, then 2x − 1.
        let pixels: Vec<f32> = image.pixels.iter().map(|&v| 2.0 * (v as f32 / 255.0) - 1.0).collect();
        let (mean, logvar) = self.vae.encode(&pixels, [1, height, width, 3])?;
        let s = self.vae.config().downscale();
        let shape = [1, height / s, width / s, self.vae.config().latent_channels];
        let std: Vec<f32> = logvar.iter().map(|v| (0.5 * v).exp()).collect();
        Ok(InitLatents { mean: nhwc_to_nchw(&mean, shape), std: nhwc_to_nchw(&std, shape) })
    }
}
