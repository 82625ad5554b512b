//! Image files as 8-bit RGB, exactly as Pillow gives them: PNG through the `png` crate and JPEG
//! through our own decoder written to libjpeg-turbo's arithmetic.

mod depth_exr;
mod grey;
mod header;
mod jpeg;
mod read;

pub use depth_exr::{read_depth_exr, read_normals_exr, read_rgb_exr};
pub use grey::{read_grey_png, GreyImage};
pub use header::{depth_exr_size, grey_png_size, image_size, normals_exr_size};
pub use read::{decode_image, read_control_image, read_image};

/// 8-bit RGB pixels, row-major, 3 bytes per pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct RgbImage {
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<u8>,
}
