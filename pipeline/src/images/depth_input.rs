//! Metric depth in an OpenEXR file as a ControlNet input (`vkdiff gen --depth`), read by
//! `vkdiff_formats::image::read_depth_exr`.

use std::path::Path;
use vkdiff_formats::image::read_depth_exr;
use vkdiff_formats::Error as FileError;
use vkdiff_render::control::{control_image, ControlDepth};

use crate::{Result, RgbImage};

/// The control image of the depth in an EXR file (per-image normalised, near = bright,
/// invalid pixels black: `vkdiff_render::control::control_image`).
pub fn depth_control_image(path: &Path, mode: ControlDepth) -> Result<RgbImage> {
    let (depth, width, height) = read_depth_exr(path)?;
    if !depth.iter().any(|&z| z.is_finite() && z > 0.0) {
        return Err(FileError::Format {
            path: path.to_path_buf(),
            why: "no pixel holds a valid depth (all are 0, negative, infinite or NaN)".into(),
        }
        .into());
    }
    Ok(RgbImage { width, height, pixels: control_image(&depth, mode) })
}
