//! The preview's geometric layers, drawn over the image where a set has them: each instance's
//! amodal outline (its whole shape, hidden parts too, dashed) and its keypoints joined by its
//! category's skeleton (a seen keypoint filled, a hidden one hollow).

use super::export::SetImage;
use serde_json::Value;
use vkdiff_render::rle::Rle;

/// A transparent RGBA picture to draw on.
pub struct Overlay {
    pub width: usize,
    pub height: usize,
    pub rgba: Vec<u8>,
}

impl Overlay {
    /// This overlay at 1/`f` of its size: each block shows the first drawn pixel in it, so thin
    /// lines survive.
    pub fn pooled(&self, f: usize) -> Overlay {
        let (sw, sh) = (self.width.div_ceil(f), self.height.div_ceil(f));
        let mut small = Overlay::new(sw, sh);
        for y in 0..self.height {
            for x in 0..self.width {
                let (p, q) = (4 * (y * self.width + x), 4 * ((y / f) * sw + x / f));
                if self.rgba[p + 3] != 0 && small.rgba[q + 3] == 0 {
                    small.rgba[q..q + 4].copy_from_slice(&self.rgba[p..p + 4]);
                }
            }
        }
        small
    }

    fn new(width: usize, height: usize) -> Overlay {
        Overlay { width, height, rgba: vec![0; width * height * 4] }
    }

    fn put(&mut self, x: i64, y: i64, [r, g, b]: [u8; 3]) {
        if (0..self.width as i64).contains(&x) && (0..self.height as i64).contains(&y) {
            let p = 4 * (y as usize * self.width + x as usize);
            self.rgba[p..p + 4].copy_from_slice(&[r, g, b, 255]);
        }
    }

    /// A one-pixel line from (x0, y0) to (x1, y1) (Bresenham's).
    fn line(&mut self, (x0, y0): (i64, i64), (x1, y1): (i64, i64), color: [u8; 3]) {
        let (dx, dy) = ((x1 - x0).abs(), -(y1 - y0).abs());
        let (sx, sy) = ((x1 - x0).signum(), (y1 - y0).signum());
        let (mut x, mut y, mut err) = (x0, y0, dx + dy);
        loop {
            self.put(x, y, color);
            if (x, y) == (x1, y1) {
                break;
            }
            let e2 = 2 * err;
            if e2 >= dy {
                err += dy;
                x += sx;
            }
            if e2 <= dx {
                err += dx;
                y += sy;
            }
        }
    }

    /// A 5×5 marker: filled when seen, a ring when hidden.
    fn marker(&mut self, x: i64, y: i64, seen: bool, color: [u8; 3]) {
        for dy in -2..=2i64 {
            for dx in -2..=2i64 {
                let ring = dx.abs() == 2 || dy.abs() == 2;
                if seen || ring {
                    self.put(x + dx, y + dy, if ring { [0, 0, 0] } else { color });
                }
            }
        }
    }
}

/// The amodal outlines of `image`'s annotations, dashed, each in its `color`; None when it has
/// none.
pub fn amodal_overlay(
    image: &SetImage,
    width: usize,
    height: usize,
    color: impl Fn(&Value) -> [u8; 3],
) -> Option<Overlay> {
    let mut overlay = Overlay::new(width, height);
    let mut any = false;
    for a in &image.annotations {
        let Some(counts) = a["amodal_segmentation"]["counts"].as_str() else { continue };
        let Ok(rle) = Rle::from_coco_string(counts, height as u32, width as u32) else { continue };
        let mask = rle.to_mask();
        let inside = |x: i64, y: i64| {
            (0..width as i64).contains(&x) && (0..height as i64).contains(&y) && mask[y as usize * width + x as usize]
        };
        for (p, _) in mask.iter().enumerate().filter(|(_, &m)| m) {
            let (x, y) = ((p % width) as i64, (p / width) as i64);
            let edge = !inside(x - 1, y) || !inside(x + 1, y) || !inside(x, y - 1) || !inside(x, y + 1);
            if edge && (x + y) % 4 < 2 {
                overlay.put(x, y, color(a));
            }
        }
        any = true;
    }
    any.then_some(overlay)
}

/// The keypoints of `image`'s annotations, each joined by its category's `skeleton` (pairs
/// numbered from 1); None when it has none.
pub fn keypoint_overlay(
    image: &SetImage,
    width: usize,
    height: usize,
    skeleton: impl Fn(&Value) -> Vec<[usize; 2]>,
    color: impl Fn(&Value) -> [u8; 3],
) -> Option<Overlay> {
    let mut overlay = Overlay::new(width, height);
    let mut any = false;
    for a in &image.annotations {
        let Some(flat) = a["keypoints"].as_array() else { continue };
        let points: Vec<Option<(i64, i64, bool)>> = flat
            .chunks(3)
            .map(|p| {
                let (x, y, v) = (p.first()?.as_f64()?, p.get(1)?.as_f64()?, p.get(2)?.as_f64()?);
                (v > 0.0).then(|| (x.round() as i64, y.round() as i64, v >= 2.0))
            })
            .collect();
        let color = color(a);
        for [i, j] in skeleton(a) {
            if let (Some(Some((x0, y0, _))), Some(Some((x1, y1, _)))) =
                (points.get(i.wrapping_sub(1)), points.get(j.wrapping_sub(1)))
            {
                overlay.line((*x0, *y0), (*x1, *y1), color);
            }
        }
        for (x, y, seen) in points.into_iter().flatten() {
            overlay.marker(x, y, seen, color);
        }
        any = true;
    }
    any.then_some(overlay)
}
