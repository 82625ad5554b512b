//! Geometric labels that a renderer gives beside its masks and that hold on the photoreal image
//! (the diffusion pass changes appearance, not geometry): keypoints and amodal masks, which move
//! with the pixels through crops, and the object's 6D pose and 3D box, which do not (a crop
//! keeps the camera's frame). Conventions:
//! - keypoints: pixel coordinates of the image as written, integer values at pixel centres
//!   (OpenCV's and COCO's convention), with COCO's visibility v: 2 seen, 1 in the image but
//!   hidden behind a surface, 0 not in the image (then x = y = 0, as COCO writes it);
//! - `pose` attribute: {"R": 3×3, "t": [x, y, z]}, the object's frame to the camera's, OpenCV
//!   camera axes (x right, y down, z forward), t in metres: X_cam = R·X_obj + t;
//! - `bbox_3d` attribute: {"min": [x, y, z], "max": [x, y, z]}, the object's axis-aligned box
//!   in its own frame, metres.

use serde_json::{json, Map, Value};

use crate::camera::Camera;

/// One keypoint: where it lies in the image and COCO's visibility flag.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Keypoint {
    pub x: f64,
    pub y: f64,
    pub v: u8,
}

impl Keypoint {
    /// A keypoint not in the image, as COCO writes one.
    pub const ABSENT: Keypoint = Keypoint { x: 0.0, y: 0.0, v: 0 };

    /// This keypoint in the `width`×`height` window at (x0, y0): shifted, and absent when it
    /// falls outside (a pixel covers ±½ around its centre).
    pub fn in_window(self, x0: u32, y0: u32, width: u32, height: u32) -> Keypoint {
        let (x, y) = (self.x - x0 as f64, self.y - y0 as f64);
        let inside = (-0.5..width as f64 - 0.5).contains(&x) && (-0.5..height as f64 - 0.5).contains(&y);
        if self.v == 0 || !inside {
            Keypoint::ABSENT
        } else {
            Keypoint { x, y, v: self.v }
        }
    }
}

/// The names of the keypoints of a 3D box, in the order [`box_keypoints`] gives them: the eight
/// corners (x, y, z each at the box's min or max, x slowest), then the centre.
pub const BOX_KEYPOINTS: [&str; 9] = [
    "corner_min_min_min",
    "corner_min_min_max",
    "corner_min_max_min",
    "corner_min_max_max",
    "corner_max_min_min",
    "corner_max_min_max",
    "corner_max_max_min",
    "corner_max_max_max",
    "center",
];

/// The box's twelve edges between [`BOX_KEYPOINTS`], numbered from 1 as COCO's skeletons are.
pub const BOX_SKELETON: [[u32; 2]; 12] =
    [[1, 2], [1, 3], [1, 5], [2, 4], [2, 6], [3, 4], [3, 7], [4, 8], [5, 6], [5, 7], [6, 8], [7, 8]];

/// A pose as the `pose` attribute holds it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObjectPose {
    pub r: [[f64; 3]; 3],
    /// Metres.
    pub t: [f64; 3],
}

impl ObjectPose {
    pub fn to_json(&self) -> Value {
        json!({"R": self.r, "t": self.t})
    }

    /// The pose of an annotation's attributes; None when it has none or it is malformed.
    pub fn of(attributes: &Map<String, Value>) -> Option<ObjectPose> {
        let pose = attributes.get("pose")?;
        Some(ObjectPose { r: serde_json::from_value(pose["R"].clone()).ok()?, t: triple(&pose["t"])? })
    }

    /// A point of the object's frame in the camera's.
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let r = &self.r;
        std::array::from_fn(|i| r[i][0] * p[0] + r[i][1] * p[1] + r[i][2] * p[2] + self.t[i])
    }
}

/// A 3D box as the `bbox_3d` attribute holds it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Box3 {
    pub min: [f64; 3],
    pub max: [f64; 3],
}

impl Box3 {
    pub fn to_json(&self) -> Value {
        json!({"min": self.min, "max": self.max})
    }

    pub fn of(attributes: &Map<String, Value>) -> Option<Box3> {
        let b = attributes.get("bbox_3d")?;
        Some(Box3 { min: triple(&b["min"])?, max: triple(&b["max"])? })
    }

    /// The corners in [`BOX_KEYPOINTS`]' order, then the centre.
    pub fn points(&self) -> [[f64; 3]; 9] {
        let (a, b) = (self.min, self.max);
        std::array::from_fn(|k| {
            if k == 8 {
                std::array::from_fn(|i| (a[i] + b[i]) / 2.0)
            } else {
                let pick = |i: usize, bit: usize| if k >> bit & 1 == 0 { a[i] } else { b[i] };
                [pick(0, 2), pick(1, 1), pick(2, 0)]
            }
        })
    }
}

fn triple(v: &Value) -> Option<[f64; 3]> {
    serde_json::from_value(v.clone()).ok()
}

/// A point whose depth lies within this fraction of the surface seen at its pixel counts as on
/// it, not behind it: a box corner on the object's own surface is seen.
const SEEN_TOLERANCE: f64 = 0.01;

/// The box's corners and centre projected by `camera` (the frame's, whose planar depth is
/// `depth`, row-major): seen where nothing nearer covers its pixel, hidden where something does,
/// absent outside the image or behind the camera.
pub fn box_keypoints(camera: &Camera, depth: &[f32], pose: &ObjectPose, bbox: &Box3) -> Vec<Keypoint> {
    let (w, h) = (camera.width as usize, camera.height as usize);
    bbox.points()
        .iter()
        .map(|&p| {
            let [x, y, z] = pose.apply(p);
            if z <= 0.0 {
                return Keypoint::ABSENT;
            }
            let (u, v) = (camera.fx * x / z + camera.cx, camera.fy * y / z + camera.cy);
            let (col, row) = ((u + 0.5).floor(), (v + 0.5).floor());
            if !(0.0..w as f64).contains(&col) || !(0.0..h as f64).contains(&row) {
                return Keypoint::ABSENT;
            }
            let surface = depth[row as usize * w + col as usize] as f64;
            let seen = surface >= z * (1.0 - SEEN_TOLERANCE);
            Keypoint { x: u, y: v, v: if seen { 2 } else { 1 } }
        })
        .collect()
}

/// An instance's whole shape, seen or hidden (its amodal mask), in its frame's pixels: the bits
/// of a window of the frame, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct AmodalMask {
    pub x0: u32,
    pub y0: u32,
    pub width: u32,
    pub height: u32,
    pub bits: Vec<bool>,
}

impl AmodalMask {
    /// The mask of a whole `width`-wide frame's `pixels`, kept to the box around its pixels;
    /// None when it has none.
    pub fn from_frame(pixels: &[bool], width: usize) -> Option<AmodalMask> {
        let on = |p: &usize| pixels[*p];
        let first = (0..pixels.len()).find(on)?;
        let last = (0..pixels.len()).rev().find(on)?;
        let (cols_lo, cols_hi) = pixels
            .chunks(width)
            .filter_map(|row| Some((row.iter().position(|&b| b)?, row.iter().rposition(|&b| b)?)))
            .fold((usize::MAX, 0), |(lo, hi), (a, b)| (lo.min(a), hi.max(b)));
        let (y0, y1) = (first / width, last / width);
        let bits = (y0..=y1).flat_map(|y| pixels[y * width + cols_lo..=y * width + cols_hi].iter().copied()).collect();
        Some(AmodalMask {
            x0: cols_lo as u32,
            y0: y0 as u32,
            width: (cols_hi - cols_lo + 1) as u32,
            height: (y1 - y0 + 1) as u32,
            bits,
        })
    }

    /// The part of the mask inside the `width`×`height` window at (x0, y0), in the window's
    /// pixels; None when none of it is.
    pub fn in_window(&self, x0: u32, y0: u32, width: u32, height: u32) -> Option<AmodalMask> {
        let (wx1, wy1) = (x0 + width, y0 + height);
        let (cx0, cy0) = (self.x0.max(x0), self.y0.max(y0));
        let (cx1, cy1) = ((self.x0 + self.width).min(wx1), (self.y0 + self.height).min(wy1));
        if cx0 >= cx1 || cy0 >= cy1 {
            return None;
        }
        let mut window = vec![false; (width * height) as usize];
        for y in cy0..cy1 {
            for x in cx0..cx1 {
                window[((y - y0) * width + (x - x0)) as usize] =
                    self.bits[((y - self.y0) * self.width + (x - self.x0)) as usize];
            }
        }
        AmodalMask::from_frame(&window, width as usize)
    }

    /// As a mask of the whole `width`×`height` image, row-major.
    pub fn to_image(&self, width: u32, height: u32) -> Vec<bool> {
        let mut image = vec![false; (width * height) as usize];
        for y in 0..self.height {
            for x in 0..self.width {
                image[((self.y0 + y) * width + self.x0 + x) as usize] = self.bits[(y * self.width + x) as usize];
            }
        }
        image
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Pose;

    #[test]
    fn keypoints_outside_a_window_are_absent_as_coco_writes_them() {
        let k = Keypoint { x: 10.0, y: 5.0, v: 2 };
        assert_eq!(k.in_window(4, 2, 8, 8), Keypoint { x: 6.0, y: 3.0, v: 2 });
        assert_eq!(k.in_window(11, 0, 8, 8), Keypoint::ABSENT, "left of the window");
        assert_eq!(k.in_window(0, 0, 10, 8), Keypoint::ABSENT, "its pixel is the 11th column");
        assert_eq!(Keypoint { v: 0, ..k }.in_window(0, 0, 20, 20), Keypoint::ABSENT);
    }

    #[test]
    fn a_cropped_camera_projects_box_corners_to_the_full_frames_pixels_less_the_offset() {
        let full = Camera::from_intrinsics(64, 48, [70.0, 72.0, 31.5, 23.5], Pose::Unknown);
        let pose = ObjectPose { r: [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], t: [0.01, -0.02, 1.0] };
        let bbox = Box3 { min: [-0.05, -0.1, -0.02], max: [0.05, 0.1, 0.02] };
        let depth = vec![f32::INFINITY; 64 * 48];
        let whole = box_keypoints(&full, &depth, &pose, &bbox);
        let crop = full.crop(10, 6, 40, 36);
        let cut: Vec<f32> = (6..42).flat_map(|y| depth[y * 64 + 10..y * 64 + 50].to_vec()).collect();
        let part = box_keypoints(&crop, &cut, &pose, &bbox);
        for (a, b) in whole.iter().zip(&part) {
            let shifted = a.in_window(10, 6, 40, 36);
            assert!(
                (shifted.x - b.x).abs() < 1e-9 && (shifted.y - b.y).abs() < 1e-9 && shifted.v == b.v,
                "{a:?} {b:?}"
            );
        }
        assert!(whole.iter().all(|k| k.v == 2), "{whole:?}");
        let centre = whole[8];
        assert!((centre.x - (31.5 + 70.0 * 0.01)).abs() < 1e-12 && (centre.y - (23.5 - 72.0 * 0.02)).abs() < 1e-12);
    }

    #[test]
    fn a_corner_behind_a_nearer_surface_is_hidden() {
        let camera = Camera::from_intrinsics(16, 16, [20.0, 20.0, 7.5, 7.5], Pose::Unknown);
        let pose = ObjectPose { r: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], t: [0.0, 0.0, 2.0] };
        let bbox = Box3 { min: [-0.1; 3], max: [0.1; 3] };
        let mut depth = vec![f32::INFINITY; 256];
        let seen = box_keypoints(&camera, &depth, &pose, &bbox);
        let pixel = |c: f64| (c + 0.5).floor() as usize;
        let centre = pixel(seen[8].y) * 16 + pixel(seen[8].x);
        depth[centre] = 1.0;
        let hidden = box_keypoints(&camera, &depth, &pose, &bbox);
        assert_eq!(hidden[8].v, 1);
        depth[centre] = 1.995;
        assert_eq!(box_keypoints(&camera, &depth, &pose, &bbox)[8].v, 2, "on its own surface");
        let behind = ObjectPose { t: [0.0, 0.0, -2.0], ..pose };
        assert!(box_keypoints(&camera, &depth, &behind, &bbox).iter().all(|k| *k == Keypoint::ABSENT));
    }

    #[test]
    fn amodal_masks_are_cut_with_the_window() {
        let (w, h) = (6usize, 5usize);
        let pixels: Vec<bool> = (0..w * h).map(|p| (1..4).contains(&(p % w)) && (1..5).contains(&(p / w))).collect();
        let mask = AmodalMask::from_frame(&pixels, w).unwrap();
        assert_eq!((mask.x0, mask.y0, mask.width, mask.height), (1, 1, 3, 4));
        assert_eq!(mask.to_image(w as u32, h as u32), pixels);
        let cut = mask.in_window(2, 0, 4, 3).unwrap();
        let expected: Vec<bool> = (0..12).map(|p| p % 4 < 2 && p / 4 >= 1).collect();
        assert_eq!(cut.to_image(4, 3), expected);
        assert!(mask.in_window(4, 0, 2, 5).is_none());
        assert!(AmodalMask::from_frame(&[false; 4], 2).is_none());
    }

    #[test]
    fn poses_and_boxes_read_back_from_attributes() {
        let pose = ObjectPose { r: [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]], t: [0.1, 0.2, 0.3] };
        let bbox = Box3 { min: [-1.0, -2.0, -3.0], max: [1.0, 2.0, 3.0] };
        let attributes = Map::from_iter([("pose".into(), pose.to_json()), ("bbox_3d".into(), bbox.to_json())]);
        assert_eq!(ObjectPose::of(&attributes), Some(pose));
        assert_eq!(Box3::of(&attributes), Some(bbox));
        assert_eq!(bbox.points()[5], [1.0, -2.0, 3.0], "{:?}", BOX_KEYPOINTS[5]);
        assert!(ObjectPose::of(&Map::from_iter([("pose".into(), json!({"R": 1}))])).is_none());
    }
}
