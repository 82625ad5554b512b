//! Image inputs, exact to the Python reference: files read as PIL reads them, Pillow's and
//! ATen's antialiased resizes, the ControlNet control tensor, CLIP preprocessing for IP-Adapter,
//! metric-depth EXR as a control image, and masks feathered and brought to the latent grid.

mod clip_preprocess;
mod control;
mod depth_input;
pub mod masks;
mod resample;

use std::path::Path;

pub use clip_preprocess::{center_crop, ClipPreprocess, ResizeTo};
pub use control::{control_size, control_tensor, VAE_SCALE_FACTOR};
pub use depth_input::depth_control_image;
pub use resample::{resize_pil, resize_torch, Filter};
pub use vkdiff_formats::image::read_depth_exr;
pub use vkdiff_formats::image::{decode_image, read_image};
pub use vkdiff_render::control::ControlDepth;

use crate::{Result, RgbImage};

/// A control image from a file: `.exr` is metric depth (made into a depth control image with
/// `mode`); any other file is an image used as it is, but for a 16-bit grey PNG (what depth
/// estimators save), which is scaled to 8 bits rather than clipped at 255 as PIL would.
pub fn load_control_image(path: &Path, mode: ControlDepth) -> Result<RgbImage> {
    let is_exr = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr"));
    if is_exr {
        depth_control_image(path, mode)
    } else {
        Ok(vkdiff_formats::image::read_control_image(path)?)
    }
}
