//! Output files: written atomically (`vkdiff_formats::atomic`, re-exported here) and PNGs that
//! carry their settings as text.

use crate::error::{Error, Result};
use crate::RgbImage;
use std::collections::BTreeMap;

pub use vkdiff_formats::atomic::{partial_path, write_atomic, write_atomic_all, write_atomic_with, PARTIAL};

/// An 8-bit RGB PNG carrying `text`: `tEXt` chunks where key and text are ASCII, uncompressed
/// `iTXt` (UTF-8) otherwise. Not `tEXt` for all of Latin-1: ComfyUI decodes `tEXt` as UTF-8, so
/// an `é` there would reach it garbled, while every reader takes ASCII either way.
pub fn png_bytes(image: &RgbImage, text: &BTreeMap<String, String>) -> Result<Vec<u8>> {
    let mut bytes = Vec::new();
    let failed = |e: png::EncodingError| Error::Config(format!("encoding a PNG: {e}"));
    let mut enc = png::Encoder::new(&mut bytes, image.width as u32, image.height as u32);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    for (k, v) in text {
        if k.is_ascii() && v.is_ascii() {
            enc.add_text_chunk(k.clone(), v.clone()).map_err(failed)?;
        } else {
            enc.add_itxt_chunk(k.clone(), v.clone()).map_err(failed)?;
        }
    }
    let mut w = enc.write_header().map_err(failed)?;
    w.write_image_data(&image.pixels).map_err(failed)?;
    w.finish().map_err(failed)?;
    Ok(bytes)
}
