//! Grey PNGs read as their stored values, not as pictures: instance maps (8- or 16-bit ids) and
//! 16-bit depth, where every value is data.

use std::path::Path;

use crate::{Error, Result};

/// A grey image's samples as stored, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct GreyImage {
    pub width: usize,
    pub height: usize,
    /// 8 or 16.
    pub bits: u8,
    pub values: Vec<u16>,
}

/// An 8- or 16-bit grey PNG (no alpha, no palette), each sample as stored.
pub fn read_grey_png(path: &Path) -> Result<GreyImage> {
    let fail = |why: String| Error::Format { path: path.to_path_buf(), why };
    let bytes = std::fs::read(path).map_err(|source| Error::Io { path: path.to_path_buf(), source })?;
    let mut reader =
        png::Decoder::new(std::io::Cursor::new(bytes)).read_info().map_err(|e| fail(format!("bad PNG: {e}")))?;
    let info = reader.info();
    let bits = grey_bits(info.color_type, info.bit_depth).map_err(fail)?;
    let (width, height) = (info.width as usize, info.height as usize);
    let mut buf = vec![0; reader.output_buffer_size().ok_or_else(|| fail("too large".into()))?];
    let frame = reader.next_frame(&mut buf).map_err(|e| fail(format!("bad PNG: {e}")))?;
    let rows = buf.chunks_exact(frame.line_size).take(height);
    let values = if bits == 8 {
        rows.flat_map(|row| row[..width].iter().map(|&v| v as u16)).collect()
    } else {
        rows.flat_map(|row| row[..2 * width].chunks_exact(2).map(|b| u16::from_be_bytes([b[0], b[1]]))).collect()
    };
    Ok(GreyImage { width, height, bits, values })
}

/// 8 or 16 for grey PNGs; anything else is not a map of values.
pub(super) fn grey_bits(color: png::ColorType, depth: png::BitDepth) -> std::result::Result<u8, String> {
    match (color, depth) {
        (png::ColorType::Grayscale, png::BitDepth::Eight) => Ok(8),
        (png::ColorType::Grayscale, png::BitDepth::Sixteen) => Ok(16),
        (color, depth) => Err(format!("{color:?} at {depth:?} bits; expected 8- or 16-bit grey (one channel of ids)")),
    }
}
