//! Image files to 8-bit RGB, as `PIL.Image.open(path).convert("RGB")` gives them: alpha dropped
//! (not composited), palettes looked up, 1/2/4-bit grey scaled to 0..255, 16-bit colour cut to
//! its high byte, and 16-bit grey (PIL mode I;16) *clipped* to 255, which is what PIL does.

use std::io::Cursor;
use std::path::Path;

use crate::{Error, Result, RgbImage};

/// Reads a PNG or JPEG file (told apart by their first bytes, not by the file name).
pub fn read_image(path: &Path) -> Result<RgbImage> {
    let bytes = std::fs::read(path).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })?;
    decode_image(&bytes, path)
}

/// Decodes PNG or JPEG bytes; `path` only names the source in errors.
pub fn decode_image(bytes: &[u8], path: &Path) -> Result<RgbImage> {
    let fail = |why: String| Error::Format {
        path: path.to_path_buf(),
        why,
    };
    if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
        decode_png(bytes).map_err(fail)
    } else if bytes.starts_with(&[0xff, 0xd8]) {
        decode_jpeg(bytes).map_err(fail)
    } else {
        Err(fail("not a PNG or JPEG file (the formats read as images)".into()))
    }
}

fn decode_png(bytes: &[u8]) -> std::result::Result<RgbImage, String> {
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
                    // PIL opens 16-bit grey as I;16 and its RGB conversion clips.
                    u16::from_be_bytes([px[2 * i], px[2 * i + 1]]).min(255) as u8
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

fn decode_jpeg(bytes: &[u8]) -> std::result::Result<RgbImage, String> {
    use zune_core::bytestream::ZCursor;
    use zune_core::colorspace::ColorSpace;
    use zune_core::options::DecoderOptions;
    let options = DecoderOptions::default().jpeg_set_out_colorspace(ColorSpace::RGB);
    let mut decoder = zune_jpeg::JpegDecoder::new_with_options(ZCursor::new(bytes), options);
    let pixels = decoder.decode().map_err(|e| format!("bad JPEG: {e:?}"))?;
    let info = decoder.info().ok_or("bad JPEG: no header")?;
    let (width, height) = (info.width as usize, info.height as usize);
    if pixels.len() != width * height * 3 {
        return Err(format!(
            "JPEG decoded to {} bytes for {width}x{height} RGB",
            pixels.len()
        ));
    }
    Ok(RgbImage { width, height, pixels })
}
