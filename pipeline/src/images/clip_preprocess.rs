//! CLIP image preprocessing as diffusers' IP-Adapter path gets it from transformers 5:
//! `CLIPImageProcessor` there is the torchvision backend, so the resize is ATen's antialiased
//! uint8 bicubic ([`resize_torch`]), not PIL's; then a centre crop (zero padding if the crop is
//! larger) and rescale + normalise fused in float32 as `(x - mean/r) / (std/r)`.

use std::path::Path;
use vkdiff_formats::Error as FileError;

use serde::Deserialize;

use super::resample::{resize_torch, Filter};
use crate::{Result, RgbImage};

const CLIP_MEAN: [f32; 3] = [0.481_454_66, 0.457_827_5, 0.408_210_73];
const CLIP_STD: [f32; 3] = [0.268_629_55, 0.261_302_6, 0.275_777_1];

/// Target size of the resize step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ResizeTo {
    /// Shorter edge to this, aspect kept (longer edge truncated).
    ShortestEdge(usize),
    Exact {
        height: usize,
        width: usize,
    },
}

/// The settings of a `CLIPImageProcessor`; [`Default`] is `CLIPImageProcessor()`.
#[derive(Clone, Debug, PartialEq)]
pub struct ClipPreprocess {
    pub do_resize: bool,
    pub size: ResizeTo,
    pub filter: Filter,
    pub do_center_crop: bool,
    /// (height, width).
    pub crop_size: (usize, usize),
    pub do_rescale: bool,
    pub rescale_factor: f64,
    pub do_normalize: bool,
    pub image_mean: [f32; 3],
    pub image_std: [f32; 3],
}

impl Default for ClipPreprocess {
    fn default() -> Self {
        Self::square(224)
    }
}

#[derive(Deserialize)]
#[serde(untagged)]
enum SizeJson {
    Int(usize),
    Map { shortest_edge: Option<usize>, height: Option<usize>, width: Option<usize>, longest_edge: Option<usize> },
}

#[derive(Deserialize)]
#[serde(untagged)]
enum Triple {
    One(f32),
    Three([f32; 3]),
}

impl Triple {
    fn get(self) -> [f32; 3] {
        match self {
            Triple::One(v) => [v; 3],
            Triple::Three(v) => v,
        }
    }
}

#[derive(Deserialize)]
struct ConfigJson {
    image_processor_type: Option<String>,
    feature_extractor_type: Option<String>,
    size: Option<SizeJson>,
    crop_size: Option<SizeJson>,
    do_resize: Option<bool>,
    do_center_crop: Option<bool>,
    do_rescale: Option<bool>,
    rescale_factor: Option<f64>,
    do_normalize: Option<bool>,
    image_mean: Option<Triple>,
    image_std: Option<Triple>,
    resample: Option<u32>,
    do_convert_rgb: Option<bool>,
}

impl ClipPreprocess {
    /// `CLIPImageProcessor(size=n, crop_size=n)`: what `load_ip_adapter` builds when the image
    /// encoder folder has no preprocessor_config.json (n = the encoder's image_size).
    pub fn square(n: usize) -> Self {
        ClipPreprocess {
            do_resize: true,
            size: ResizeTo::ShortestEdge(n),
            filter: Filter::Bicubic,
            do_center_crop: true,
            crop_size: (n, n),
            do_rescale: true,
            rescale_factor: 1.0 / 255.0,
            do_normalize: true,
            image_mean: CLIP_MEAN,
            image_std: CLIP_STD,
        }
    }

    /// Reads a preprocessor_config.json; keys not listed here are ignored.
    pub fn from_file(path: &Path) -> Result<Self> {
        let text =
            std::fs::read_to_string(path).map_err(|source| FileError::Io { path: path.to_path_buf(), source })?;
        Ok(Self::from_json(&text).map_err(|why| FileError::Format { path: path.to_path_buf(), why })?)
    }

    pub fn from_json(text: &str) -> std::result::Result<Self, String> {
        let c: ConfigJson = serde_json::from_str(text).map_err(|e| format!("bad preprocessor config: {e}"))?;
        for kind in [&c.image_processor_type, &c.feature_extractor_type].into_iter().flatten() {
            if !matches!(kind.as_str(), "CLIPImageProcessor" | "CLIPImageProcessorFast" | "CLIPFeatureExtractor") {
                return Err(format!("image processor {kind:?} is not CLIP's (CLIPImageProcessor); not supported"));
            }
        }
        let mut p = Self::default();
        if let Some(size) = c.size {
            p.size = match size {
                SizeJson::Int(n) => ResizeTo::ShortestEdge(n),
                SizeJson::Map { longest_edge: Some(_), .. } => return Err("size.longest_edge is not supported".into()),
                SizeJson::Map { shortest_edge: Some(n), .. } => ResizeTo::ShortestEdge(n),
                SizeJson::Map { height: Some(height), width: Some(width), .. } => ResizeTo::Exact { height, width },
                _ => return Err("size needs shortest_edge, or height and width".into()),
            };
        }
        if let Some(crop) = c.crop_size {
            p.crop_size = match crop {
                SizeJson::Int(n) => (n, n),
                SizeJson::Map { height: Some(h), width: Some(w), .. } => (h, w),
                _ => return Err("crop_size needs height and width".into()),
            };
        }
        p.filter = match c.resample.unwrap_or(3) {
            3 => Filter::Bicubic,
            2 => Filter::Bilinear,
            other => return Err(format!("resample {other} is not supported (3 = bicubic, 2 = bilinear)")),
        };
        if c.do_convert_rgb == Some(false) {
            return Err("do_convert_rgb false is not supported (inputs are read as RGB)".into());
        }
        p.do_resize = c.do_resize.unwrap_or(p.do_resize);
        p.do_center_crop = c.do_center_crop.unwrap_or(p.do_center_crop);
        p.do_rescale = c.do_rescale.unwrap_or(p.do_rescale);
        p.rescale_factor = c.rescale_factor.unwrap_or(p.rescale_factor);
        p.do_normalize = c.do_normalize.unwrap_or(p.do_normalize);
        p.image_mean = c.image_mean.map_or(p.image_mean, Triple::get);
        p.image_std = c.image_std.map_or(p.image_std, Triple::get);
        if p.do_resize
            && matches!(
                p.size,
                ResizeTo::ShortestEdge(0) | ResizeTo::Exact { height: 0, .. } | ResizeTo::Exact { width: 0, .. }
            )
        {
            return Err("size 0".into());
        }
        if p.do_center_crop && (p.crop_size.0 == 0 || p.crop_size.1 == 0) {
            return Err("crop_size 0".into());
        }
        Ok(p)
    }

    /// Output (height, width) of the resize step for an input of `height`×`width`, as
    /// transformers' `get_resize_output_image_size(default_to_square=False)` computes it.
    pub fn resized_size(&self, height: usize, width: usize) -> (usize, usize) {
        match self.size {
            ResizeTo::Exact { height, width } => (height, width),
            ResizeTo::ShortestEdge(n) => {
                let (short, long) = if width <= height { (width, height) } else { (height, width) };
                let new_long = ((n * long) as f64 / short as f64) as usize;
                if width <= height {
                    (new_long, n)
                } else {
                    (n, new_long)
                }
            }
        }
    }

    /// `pixel_values` of `processor(image, return_tensors="pt")`: NCHW [1, 3, H, W] float32,
    /// with the shape.
    pub fn apply(&self, image: &RgbImage) -> (Vec<f32>, [usize; 4]) {
        let mut img = image.clone();
        if self.do_resize {
            let (h, w) = self.resized_size(img.height, img.width);
            if (h, w) != (img.height, img.width) {
                img = resize_torch(&img, w, h, self.filter);
            }
        }
        if self.do_center_crop {
            img = center_crop(&img, self.crop_size.0, self.crop_size.1);
        }
        let (h, w) = (img.height, img.width);
        // transformers fuses rescale into normalise: mean and std scaled by 1/factor in float32.
        let inv = (1.0 / self.rescale_factor) as f32;
        let mut out = vec![0f32; 3 * h * w];
        for c in 0..3 {
            let (mean, std) = (self.image_mean[c] * inv, self.image_std[c] * inv);
            for i in 0..h * w {
                let x = img.pixels[i * 3 + c] as f32;
                out[c * h * w + i] = match (self.do_normalize, self.do_rescale) {
                    (true, true) => (x - mean) / std,
                    (true, false) => (x - self.image_mean[c]) / self.image_std[c],
                    (false, true) => x * self.rescale_factor as f32,
                    (false, false) => x,
                };
            }
        }
        (out, [1, 3, h, w])
    }
}

/// torchvision's centre crop: zero padding (left/top get the smaller half) when the crop is
/// larger than the image, then offsets `int((size - crop) / 2.0)`.
pub fn center_crop(image: &RgbImage, crop_h: usize, crop_w: usize) -> RgbImage {
    let (mut img, mut off_y, mut off_x) = (image.clone(), 0usize, 0usize);
    if crop_w > img.width || crop_h > img.height {
        let pad_l = crop_w.saturating_sub(img.width) / 2;
        let pad_t = crop_h.saturating_sub(img.height) / 2;
        let (w, h) = (img.width.max(crop_w), img.height.max(crop_h));
        let mut pixels = vec![0u8; w * h * 3];
        for y in 0..img.height {
            let dst = ((y + pad_t) * w + pad_l) * 3;
            pixels[dst..dst + img.width * 3].copy_from_slice(&img.pixels[y * img.width * 3..(y + 1) * img.width * 3]);
        }
        img = RgbImage { width: w, height: h, pixels };
    }
    if (img.width, img.height) != (crop_w, crop_h) {
        off_y = ((img.height - crop_h) as f64 / 2.0) as usize;
        off_x = ((img.width - crop_w) as f64 / 2.0) as usize;
    }
    let mut pixels = Vec::with_capacity(crop_w * crop_h * 3);
    for y in off_y..off_y + crop_h {
        let row = (y * img.width + off_x) * 3;
        pixels.extend_from_slice(&img.pixels[row..row + crop_w * 3]);
    }
    RgbImage { width: crop_w, height: crop_h, pixels }
}
