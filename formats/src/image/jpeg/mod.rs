//! JPEG decoded as `PIL.Image.open(f).convert("RGB")` decodes it, byte for byte: Pillow hands the
//! file to libjpeg-turbo with its defaults (the accurate integer IDCT, "fancy" triangular chroma
//! upsampling, its fixed-point YCbCr → RGB tables) and converts CMYK itself. This is our own
//! decoder written to that arithmetic, so FID over JPEG photos is torch-fidelity's.
//!
//! Read: baseline, extended (8-bit) and progressive Huffman JPEG (sequential files without Huffman
//! tables, as motion-JPEG frames come, take the standard ones); greyscale, YCbCr, RGB, CMYK and
//! YCCK (colour space chosen from JFIF/Adobe markers and component ids as libjpeg-turbo does);
//! any sampling factors libjpeg-turbo takes; restart markers (with its resynchronisation); data
//! that ends early at a marker (libjpeg-turbo leaves the rest of the scan grey or unrefined, as
//! Pillow shows it). EXIF orientation is ignored, as Pillow's `open` and torch-fidelity ignore it.
//! Refused with a reason: arithmetic coding, lossless and hierarchical JPEG, 12-bit samples, files
//! that end before the image is complete (Pillow: "image file is truncated").
//! Not reproduced: libjpeg-turbo's inter-block smoothing of progressive files that never send some
//! low-frequency coefficients in full (no encoder we know of writes such files).

mod entropy;
mod frame;
mod idct;
mod output;
mod standard_huffman;

use super::RgbImage;

/// Pillow's `Image.MAX_IMAGE_PIXELS` × 2: above this, `open` raises DecompressionBombError.
const MAX_PIXELS: u64 = 2 * 89_478_485;

/// Decodes a JPEG file's bytes to 8-bit RGB, or says why it cannot.
pub fn decode_jpeg(bytes: &[u8]) -> Result<RgbImage, String> {
    output::to_rgb(&frame::decode(bytes)?)
}
