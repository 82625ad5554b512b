//! Image files to 8-bit RGB, as `PIL.Image.open(path).convert("RGB")` gives them: alpha dropped
//! (not composited), palettes looked up, 1/2/4-bit grey scaled to 0..255, 16-bit colour cut to
//! its high byte, and 16-bit grey (PIL mode I;16) *clipped* to 255, which is what PIL does.

use std::io::Cursor;
use std::path::Path;

use super::RgbImage;
use crate::{Error, Result};

/// Reads a PNG or JPEG file (told apart by their first bytes, not by the file name).
pub fn read_image(path: &Path) -> Result<RgbImage> {
    let bytes = std::fs::read(path).map_err(|source| Error::Io { path: path.to_path_buf(), source })?;
    decode_image(&bytes, path)
}

/// [`read_image`], but a 16-bit grey PNG keeps its range: each sample scaled to 8 bits.
pub fn read_control_image(path: &Path) -> Result<RgbImage> {
    let bytes = std::fs::read(path).map_err(|source| Error::Io { path: path.to_path_buf(), source })?;
    let fail = |why: String| Error::Format { path: path.to_path_buf(), why };
    if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
        return decode_png(&bytes, Grey16::Scale).map_err(fail);
    }
    decode_image(&bytes, path)
}

/// What becomes of 16-bit grey samples.
#[derive(Clone, Copy, PartialEq)]
enum Grey16 {
    /// PIL's `convert("RGB")` of mode I;16: values above 255 become 255.
    Clip,
    /// Round(v · 255 / 65535): the whole range kept.
    Scale,
}

/// Decodes PNG or JPEG bytes; `path` only names the source in errors.
pub fn decode_image(bytes: &[u8], path: &Path) -> Result<RgbImage> {
    let fail = |why: String| Error::Format { path: path.to_path_buf(), why };
    if bytes.is_empty() {
        Err(fail("empty file".into()))
    } else if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
        decode_png(bytes, Grey16::Clip).map_err(fail)
    } else if bytes.starts_with(&[0xff, 0xd8]) {
        super::jpeg::decode_jpeg(bytes).map_err(fail)
    } else {
        Err(fail("not a PNG or JPEG file (the formats read as images)".into()))
    }
}

fn decode_png(bytes: &[u8], grey16: Grey16) -> std::result::Result<RgbImage, String> {
    use png::{BitDepth, ColorType, Transformations};
    let mut decoder = png::Decoder::new(Cursor::new(bytes));
    // EXPAND: palettes to RGB, low-bit grey to 8 bits (scaled), tRNS to alpha; 16 bits stay.
    decoder.set_transformations(Transformations::EXPAND);
    let mut reader = decoder.read_info().map_err(|e| format!("bad PNG: {e}"))?;
    let source_type = reader.info().color_type;
    let (color, depth) = reader.output_color_type();
    let size = reader.output_buffer_size().ok_or("PNG too large")?;
    let mut buf = vec![0; size];
    let frame = reader.next_frame(&mut buf).map_err(|e| format!("bad PNG: {e}"))?;
    let (width, height) = (frame.width as usize, frame.height as usize);
    let channels = color.samples();
    let bytes_per_sample = if depth == BitDepth::Sixteen { 2 } else { 1 };
    let mut pixels = Vec::with_capacity(width * height * 3);
    for row in buf.chunks_exact(frame.line_size).take(height) {
        for px in row.chunks_exact(channels * bytes_per_sample).take(width) {
            let sample = |i: usize| -> u8 {
                if bytes_per_sample == 1 {
                    px[i]
                } else if source_type == ColorType::Grayscale {
                    let v = u16::from_be_bytes([px[2 * i], px[2 * i + 1]]);
                    match grey16 {
                        Grey16::Clip => v.min(255) as u8,
                        Grey16::Scale => ((v as u32 * 255 + 32767) / 65535) as u8,
                    }
                } else {
                    px[2 * i]
                }
            };
            match color {
                ColorType::Grayscale | ColorType::GrayscaleAlpha => pixels.extend([sample(0); 3]),
                ColorType::Rgb | ColorType::Rgba => pixels.extend([sample(0), sample(1), sample(2)]),
                ColorType::Indexed => return Err("palette not expanded".into()),
            }
        }
    }
    Ok(RgbImage { width, height, pixels })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sixteen_bit_grey_is_clipped_as_pil_does_for_images_and_scaled_for_control() {
        let values: [u16; 4] = [0, 255, 32896, 65535];
        let mut bytes = Vec::new();
        let mut enc = png::Encoder::new(&mut bytes, 4, 1);
        enc.set_color(png::ColorType::Grayscale);
        enc.set_depth(png::BitDepth::Sixteen);
        let mut w = enc.write_header().unwrap();
        w.write_image_data(&values.iter().flat_map(|v| v.to_be_bytes()).collect::<Vec<u8>>()).unwrap();
        w.finish().unwrap();
        let path = std::env::temp_dir().join(format!("vkdiff-grey16-{}.png", std::process::id()));
        std::fs::write(&path, &bytes).unwrap();
        let grey = |image: RgbImage| image.pixels.chunks(3).map(|p| p[0]).collect::<Vec<u8>>();
        assert_eq!(grey(read_image(&path).unwrap()), [0, 255, 255, 255]);
        assert_eq!(grey(read_control_image(&path).unwrap()), [0, 1, 128, 255]);
        std::fs::remove_file(path).unwrap();
    }
}
