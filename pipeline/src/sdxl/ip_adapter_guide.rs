//! IP-Adapter style images as diffusers' SDXL pipeline feeds them: every image through the CLIP
//! preprocessing and vision encoder, projected to image tokens laid one after another for the one
//! adapter, and for guidance the negative tokens diffusers makes (zero embeds, or the encoder's
//! output for zero pixels).

use crate::error::{Error, Result};
use crate::images::ClipPreprocess;
use crate::settings::ip_scale::IpScale;
use crate::RgbImage;
use vkdiff_networks::{ClipVisionModelWithProjection, ImageFeature, IpAdapter};
use vkdiff_setting::Message;

/// The `--ip-adapter` settings of one generation.
pub struct ImageGuide<'a> {
    pub adapter: &'a IpAdapter,
    pub encoder: &'a ClipVisionModelWithProjection,
    pub preprocess: &'a ClipPreprocess,
    /// The style images, all for the one adapter.
    pub images: &'a [RgbImage],
    pub scale: &'a IpScale,
}

impl ImageGuide<'_> {
    /// The image tokens [rows, images · tokens per image, width] of the rows [negative, positive]
    /// (`guided`) or [positive], row-major.
    pub fn tokens(&self, guided: bool) -> Result<Vec<f32>> {
        if self.images.is_empty() {
            return Err(Error::Setting(Message::setting("ip_adapter").then(" needs at least one ").and("ip_image")));
        }
        let feature = self.adapter.kind().feature();
        let mut pixels = Vec::new();
        let mut size = [0; 4];
        for image in self.images {
            let (values, shape) = self.preprocess.apply(image);
            pixels.extend(values);
            size = shape;
        }
        let n = self.images.len();
        let positive = self.encode_tokens(&pixels, n, feature)?;
        let mut tokens = Vec::new();
        if guided {
            let negative = match feature {
                ImageFeature::ImageEmbeds => {
                    let width = self.encoder.config().projection_dim;
                    self.adapter.image_tokens(&vec![0.0; n * width], &[n, width])?
                }
                ImageFeature::Penultimate => {
                    self.encode_tokens(&vec![0.0; n * size[1] * size[2] * size[3]], n, feature)?
                }
            };
            tokens.extend(negative);
        }
        tokens.extend(positive);
        Ok(tokens)
    }

    /// The image tokens of `n` preprocessed images, one image's after another.
    fn encode_tokens(&self, pixels: &[f32], n: usize, feature: ImageFeature) -> Result<Vec<f32>> {
        let encoding = self.encoder.encode(pixels, n, &[feature])?;
        let (features, shape) = encoding.get(feature).expect("the encoder computes what it is asked for");
        Ok(self.adapter.image_tokens(features, &shape)?)
    }
}
