//! Square crops of a frame, as the paper cut three 1024×1024 images out of each 1920×1080
//! render: windows inside the frame at positions drawn from the scene seed, each with its own
//! depth, masks (instances clipped to the window, slivers dropped, ids renumbered 1..n) and
//! camera (principal point shifted by the window's offset).

use crate::error::{RenderError, Result};
use crate::frame::{pixel_counts, renumber, Frame};
use crate::rng::{Rng, Stream};
use vkdiff_setting::Message;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CropWindow {
    pub x0: u32,
    pub y0: u32,
    pub width: u32,
    pub height: u32,
}

/// The largest window of a `width`×`height` frame whose sides are multiples of `multiple`,
/// centred (odd leftovers go to the right and bottom): whole frames cut to a size a model can
/// make, rather than stretched.
pub fn centered_window(width: u32, height: u32, multiple: u32) -> Result<CropWindow> {
    let (w, h) = (width - width % multiple.max(1), height - height % multiple.max(1));
    if w == 0 || h == 0 {
        return Err(RenderError::Setting(
            Message::setting("width")
                .then("/")
                .and("height")
                .then(format!(" {width}×{height}: the model needs sides of at least {multiple} pixels")),
        ));
    }
    Ok(centered(width, height, w, h))
}

/// The `w`×`h` window in the middle of a `width`×`height` frame (odd leftovers to the right and
/// bottom).
pub fn centered(width: u32, height: u32, w: u32, h: u32) -> CropWindow {
    CropWindow { x0: (width - w) / 2, y0: (height - h) / 2, width: w, height: h }
}

/// `count` windows of `size`² inside a `width`×`height` frame, from the scene seed alone.
pub fn crop_windows(seed: u64, count: usize, size: u32, width: u32, height: u32) -> Result<Vec<CropWindow>> {
    if count > 0 && (size == 0 || size > width || size > height) {
        return Err(RenderError::invalid(
            "crop_size",
            size,
            format!("must lie in [1, {}] to fit the {width}×{height} frame", width.min(height)),
        ));
    }
    let mut rng = Rng::stream(seed, Stream::Crops);
    Ok((0..count)
        .map(|_| CropWindow {
            x0: rng.below((width - size + 1) as u64) as u32,
            y0: rng.below((height - size + 1) as u64) as u32,
            width: size,
            height: size,
        })
        .collect())
}

/// The part of `frame` under `window`. An instance stays when at least `min_fraction` of its
/// visible pixels in the full frame fall inside the window (SAHI's `min_area_ratio`, 0.1 by
/// default); the pixels of dropped slivers become background.
pub fn crop_frame(frame: &Frame, window: CropWindow, min_fraction: f64) -> Frame {
    let (w, cw) = (frame.width(), window.width as usize);
    let rows = (window.y0 as usize..(window.y0 + window.height) as usize)
        .map(|y| y * w + window.x0 as usize..y * w + window.x0 as usize + cw);
    let mut ids: Vec<u16> = rows.clone().flat_map(|r| frame.ids[r].iter().copied()).collect();
    let depth: Vec<f32> = rows.clone().flat_map(|r| frame.depth[r].iter().copied()).collect();
    let normals = frame.normals.as_ref().map(|n| rows.flat_map(|r| n[r].iter().copied()).collect());
    let labels = frame.instances.len() + 1;
    let in_frame = pixel_counts(&frame.ids, labels);
    let in_crop = pixel_counts(&ids, labels);
    let kept =
        renumber(&mut ids, labels, |id| in_crop[id] > 0 && in_crop[id] as f64 >= min_fraction * in_frame[id] as f64);
    let instances = kept
        .iter()
        .map(|&id| frame.instances[id - 1].in_window(window.x0, window.y0, window.width, window.height))
        .collect();
    Frame {
        width: window.width,
        height: window.height,
        camera: frame.camera.as_ref().map(|c| c.crop(window.x0, window.y0, window.width, window.height)),
        depth,
        ids,
        instances,
        normals,
    }
}

pub fn validate_min_fraction(min_fraction: f64) -> Result<()> {
    if (0.0..=1.0).contains(&min_fraction) {
        Ok(())
    } else {
        Err(RenderError::invalid("crop_min_fraction", min_fraction, "must lie in [0, 1]"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn windows_fit_the_frame_and_follow_the_seed() {
        for seed in 0..50 {
            let windows = crop_windows(seed, 3, 1024, 1920, 1080).unwrap();
            assert_eq!(windows, crop_windows(seed, 3, 1024, 1920, 1080).unwrap());
            assert!(windows.iter().all(|c| c.x0 + 1024 <= 1920 && c.y0 + 1024 <= 1080));
        }
        assert_ne!(crop_windows(1, 3, 512, 1920, 1080).unwrap(), crop_windows(2, 3, 512, 1920, 1080).unwrap());
        assert_eq!(crop_windows(0, 1, 1080, 1920, 1080).unwrap()[0].y0, 0);
        let err = crop_windows(0, 3, 2000, 1920, 1080).unwrap_err().to_string();
        assert!(err.contains("crop_size 2000"), "{err}");
        assert!(crop_windows(0, 0, 2000, 1920, 1080).unwrap().is_empty(), "no crops, nothing to check");
    }

    #[test]
    fn centered_windows_are_the_largest_multiple_and_centred() {
        assert_eq!(centered_window(1920, 1080, 32).unwrap(), CropWindow { x0: 0, y0: 12, width: 1920, height: 1056 });
        assert_eq!(centered_window(101, 64, 32).unwrap(), CropWindow { x0: 2, y0: 0, width: 96, height: 64 });
        assert!(centered_window(20, 64, 32).unwrap_err().to_string().contains("at least 32"));
    }

    #[test]
    fn the_renderers_normals_are_cut_with_the_frame() {
        use crate::frame::Instance;
        let (w, h) = (5usize, 4usize);
        let frame = Frame {
            width: w as u32,
            height: h as u32,
            camera: None,
            depth: vec![2.0; w * h],
            ids: vec![1; w * h],
            instances: vec![Instance { category_id: 1, ..Instance::default() }],
            normals: Some((0..w * h).map(|p| [p as f32, -(p as f32), 1.0]).collect()),
        };
        let crop = crop_frame(&frame, CropWindow { x0: 1, y0: 2, width: 3, height: 2 }, 0.0);
        let firsts: Vec<f32> = crop.normals.unwrap().iter().map(|n| n[0]).collect();
        assert_eq!(firsts, [11.0, 12.0, 13.0, 16.0, 17.0, 18.0]);
        let without =
            crop_frame(&Frame { normals: None, ..frame }, CropWindow { x0: 0, y0: 0, width: 2, height: 2 }, 0.0);
        assert!(without.normals.is_none());
    }
}
