//! PNG encoding of the frame's images into memory: 16-bit grayscale ids and 8-bit RGB pictures.

use png::{BitDepth, ColorType, Compression, Encoder};

fn encode(width: u32, height: u32, color: ColorType, depth: BitDepth, data: &[u8]) -> Vec<u8> {
    let mut bytes = Vec::new();
    let mut encoder = Encoder::new(&mut bytes, width, height);
    encoder.set_color(color);
    encoder.set_depth(depth);
    // fdeflate: several times faster than zlib at a slightly larger file, which suits
    // label images (long runs) and a dataset writer that runs on every core.
    encoder.set_compression(Compression::Fast);
    let mut writer = encoder.write_header().expect("writing to memory cannot fail");
    writer.write_image_data(data).expect("image data matches its header");
    writer.finish().expect("writing to memory cannot fail");
    bytes
}

/// Single-channel 16-bit PNG (PNG stores samples big-endian).
pub fn gray16(width: u32, height: u32, samples: &[u16]) -> Vec<u8> {
    let data: Vec<u8> = samples.iter().flat_map(|s| s.to_be_bytes()).collect();
    encode(width, height, ColorType::Grayscale, BitDepth::Sixteen, &data)
}

/// 8-bit RGB PNG from interleaved samples.
pub fn rgb8(width: u32, height: u32, rgb: &[u8]) -> Vec<u8> {
    encode(width, height, ColorType::Rgb, BitDepth::Eight, rgb)
}

/// Single-channel 8-bit PNG.
pub fn gray8(width: u32, height: u32, samples: &[u8]) -> Vec<u8> {
    encode(width, height, ColorType::Grayscale, BitDepth::Eight, samples)
}
