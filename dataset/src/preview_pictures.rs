//! The pictures a preview shows: masks and depth read from a set's files, images scaled down
//! for the contact sheet, and PNGs encoded for a self-contained page.

use crate::error::Result;
use std::path::Path;
use vkdiff_formats::Error as FileError;
use vkdiff_pipeline::images::read_depth_exr;
use vkdiff_pipeline::RgbImage;

/// `image` averaged over `f`×`f` blocks (those at the right and bottom edges cut short).
pub(crate) fn box_down(image: &RgbImage, f: usize) -> RgbImage {
    if f == 1 {
        return image.clone();
    }
    let (w, h) = (image.width, image.height);
    let (sw, sh) = (w.div_ceil(f), h.div_ceil(f));
    let mut pixels = Vec::with_capacity(sw * sh * 3);
    for by in 0..sh {
        for bx in 0..sw {
            let (ys, xs) = (by * f..((by + 1) * f).min(h), bx * f..((bx + 1) * f).min(w));
            let n = (ys.len() * xs.len()) as u32;
            for c in 0..3 {
                let sum: u32 = ys
                    .clone()
                    .flat_map(|y| xs.clone().map(move |x| (y, x)))
                    .map(|(y, x)| image.pixels[3 * (y * w + x) + c] as u32)
                    .sum();
                pixels.push(((sum + n / 2) / n) as u8);
            }
        }
    }
    RgbImage { width: sw, height: sh, pixels }
}

/// A mask PNG's 16-bit instance ids, checked against the image's size.
pub(crate) fn read_ids(path: &Path, width: usize, height: usize) -> Result<Vec<u16>> {
    let grey = vkdiff_formats::image::read_grey_png(path)?;
    if grey.bits != 16 || (grey.width, grey.height) != (width, height) {
        let why = format!("not a {width}×{height} 16-bit grey instance mask");
        return Err(FileError::Format { path: path.to_path_buf(), why }.into());
    }
    Ok(grey.values)
}

/// The depth as grey, near bright, stretched over its finite range.
pub(crate) fn depth_picture(path: &Path) -> Result<RgbImage> {
    let (depth, width, height) = read_depth_exr(path)?;
    let finite = depth.iter().copied().filter(|d| d.is_finite());
    let (near, far) = finite.fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), d| (a.min(d), b.max(d)));
    let span = (far - near).max(1e-6);
    let grey: Vec<u8> = depth
        .iter()
        .flat_map(|&d| {
            let v = if d.is_finite() { (255.0 * (far - d) / span).round() as u8 } else { 0 };
            [v; 3]
        })
        .collect();
    Ok(RgbImage { width, height, pixels: grey })
}

pub(crate) fn rgba_png(width: u32, height: u32, rgba: &[u8]) -> Vec<u8> {
    let mut bytes = Vec::new();
    let mut encoder = png::Encoder::new(&mut bytes, width, height);
    encoder.set_color(png::ColorType::Rgba);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header().expect("writing to memory cannot fail");
    writer.write_image_data(rgba).expect("data matches its header");
    writer.finish().expect("writing to memory cannot fail");
    bytes
}

/// A PNG as a `data:` URI, for self-contained pages.
pub fn data_uri(png: &[u8]) -> String {
    const DIGITS: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut text = String::with_capacity(22 + png.len().div_ceil(3) * 4);
    text.push_str("data:image/png;base64,");
    for chunk in png.chunks(3) {
        let b = [chunk[0], *chunk.get(1).unwrap_or(&0), *chunk.get(2).unwrap_or(&0)];
        let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        for k in 0..4 {
            if k <= chunk.len() {
                text.push(DIGITS[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                text.push('=');
            }
        }
    }
    text
}

/// Text made safe for HTML.
pub fn escape(text: &str) -> String {
    text.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}
