//! The pinhole camera: Blender's default camera (50 mm lens, 36 mm sensor, sensor fit AUTO)
//! looking straight down at the bed, described as OpenCV intrinsics and as poses in both the
//! OpenCV and the Blender camera conventions.
//!
//! Conventions, stated once and written into camera.json:
//! - world: right-handed, metres, z up, the ground near z = 0;
//! - OpenCV camera axes: x right, y down, z forward (the viewing direction); the camera looks
//!   along world −z, so image right is world +x and image down is world −y;
//! - pixel coordinates: integer values are pixel centres (OpenCV), so a centred principal point
//!   is ((W−1)/2, (H−1)/2), and pixel (u, v) covers [u−½, u+½] × [v−½, v+½];
//! - depth: planar, the camera-space z, not the distance along the ray.

use serde_json::{json, Value};

use crate::math::Vec3;
use crate::poisson::Rect;

#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub lens_mm: f64,
    pub sensor_width_mm: f64,
    /// Camera centre in the world.
    pub position: Vec3,
    /// Where this image's pixel (0, 0) lies in the full frame; non-zero for crops.
    pub crop_offset: (u32, u32),
    /// How the camera is placed in the world.
    pub pose: Pose,
}

/// A camera's placement in the world.
#[derive(Clone, Debug, PartialEq)]
pub enum Pose {
    /// At `position`, looking straight down (the procedural bed's camera): what [`Camera::project`],
    /// [`Camera::ray_direction`] and [`Camera::footprint`] assume.
    TopDown,
    /// T_world_camera in OpenCV's camera axes (x right, y down, z forward), metres, row-major 4×4,
    /// as a renderer gave it (a BOP scene's `cam_R_w2c`, `cam_t_w2c`, inverted).
    Given([[f64; 4]; 4]),
    /// Not given: only the intrinsics are known.
    Unknown,
}

impl Camera {
    /// A camera at `position` looking straight down. Blender's AUTO sensor fit applies the
    /// sensor width to the longer image side.
    pub fn top_down(width: u32, height: u32, lens_mm: f64, sensor_width_mm: f64, position: Vec3) -> Camera {
        let focal_px = lens_mm / sensor_width_mm * width.max(height) as f64;
        Camera {
            width,
            height,
            fx: focal_px,
            fy: focal_px,
            cx: (width as f64 - 1.0) / 2.0,
            cy: (height as f64 - 1.0) / 2.0,
            lens_mm,
            sensor_width_mm,
            position,
            crop_offset: (0, 0),
            pose: Pose::TopDown,
        }
    }

    /// A camera known by its intrinsics (pixels, OpenCV's convention) and perhaps its pose; its
    /// lens is recorded as the focal length on a 36 mm sensor spanning the longer image side.
    pub fn from_intrinsics(width: u32, height: u32, [fx, fy, cx, cy]: [f64; 4], pose: Pose) -> Camera {
        let sensor_width_mm = 36.0;
        let position = match &pose {
            Pose::Given(m) => Vec3::new(m[0][3], m[1][3], m[2][3]),
            _ => Vec3::new(0.0, 0.0, 0.0),
        };
        let lens_mm = fx * sensor_width_mm / width.max(height) as f64;
        Camera { width, height, fx, fy, cx, cy, lens_mm, sensor_width_mm, position, crop_offset: (0, 0), pose }
    }

    /// World point to OpenCV camera coordinates; z is the planar depth.
    pub fn to_camera(&self, p: Vec3) -> Vec3 {
        Vec3::new(p.x - self.position.x, self.position.y - p.y, self.position.z - p.z)
    }

    /// World point to (u, v, depth).
    pub fn project(&self, p: Vec3) -> (f64, f64, f64) {
        let c = self.to_camera(p);
        (self.fx * c.x / c.z + self.cx, self.fy * c.y / c.z + self.cy, c.z)
    }

    /// World-space direction of the ray through pixel coordinates (u, v), scaled so that its
    /// component along the viewing axis is 1 (so `t` along it is the planar depth).
    pub fn ray_direction(&self, u: f64, v: f64) -> Vec3 {
        Vec3::new((u - self.cx) / self.fx, -(v - self.cy) / self.fy, -1.0)
    }

    /// The part of the horizontal plane at height `z` that the image covers (pixel edges).
    pub fn footprint(&self, z: f64) -> Rect {
        let depth = self.position.z - z;
        let (u0, u1) = (-0.5, self.width as f64 - 0.5);
        let (v0, v1) = (-0.5, self.height as f64 - 0.5);
        let x = |u: f64| self.position.x + (u - self.cx) / self.fx * depth;
        let y = |v: f64| self.position.y - (v - self.cy) / self.fy * depth;
        Rect { x0: x(u0), x1: x(u1), y0: y(v1), y1: y(v0) }
    }

    /// The camera of the `width`×`height` window at (x0, y0) of this image: same pose, the
    /// principal point shifted by the offset.
    pub fn crop(&self, x0: u32, y0: u32, width: u32, height: u32) -> Camera {
        Camera {
            width,
            height,
            cx: self.cx - x0 as f64,
            cy: self.cy - y0 as f64,
            crop_offset: (self.crop_offset.0 + x0, self.crop_offset.1 + y0),
            ..self.clone()
        }
    }

    /// Size of one pixel on a plane at `depth`, metres.
    pub fn pixel_footprint(&self, depth: f64) -> f64 {
        depth / self.fx
    }

    pub fn to_json(&self) -> Value {
        let p = self.position;
        let (opencv, blender) = match &self.pose {
            Pose::TopDown => (
                json!([[1.0, 0.0, 0.0, p.x], [0.0, -1.0, 0.0, p.y], [0.0, 0.0, -1.0, p.z], [0.0, 0.0, 0.0, 1.0]]),
                json!([[1.0, 0.0, 0.0, p.x], [0.0, 1.0, 0.0, p.y], [0.0, 0.0, 1.0, p.z], [0.0, 0.0, 0.0, 1.0]]),
            ),
            // Blender's camera axes are OpenCV's with y and z turned: its columns 1 and 2 negated.
            Pose::Given(m) => {
                let flip = |r: &[f64; 4]| [r[0], -r[1], -r[2], r[3]];
                (json!(m), json!(m.iter().map(flip).collect::<Vec<_>>()))
            }
            Pose::Unknown => (Value::Null, Value::Null),
        };
        let matrix = |m: Value, axes: &str| if m.is_null() { m } else { json!({"axes": axes, "matrix": m}) };
        json!({
            "width": self.width,
            "height": self.height,
            "K": [[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]],
            "distortion": [0.0, 0.0, 0.0, 0.0, 0.0],
            "lens_mm": self.lens_mm,
            "sensor_width_mm": self.sensor_width_mm,
            "sensor_fit": "AUTO (sensor width spans the longer image side)",
            "crop_offset_px": [self.crop_offset.0, self.crop_offset.1],
            "pixel_centers": "integer pixel coordinates are pixel centres (OpenCV)",
            "depth": "depth.exr channel Z: planar depth (camera-space z) in metres",
            "world": match self.pose {
                Pose::TopDown => "right-handed, metres, z up, ground plane near z = 0",
                _ => "the renderer's world, metres",
            },
            "T_world_camera_opencv": matrix(opencv, "x right, y down, z forward"),
            "T_world_camera_blender": matrix(blender, "x right, y up, z backward (Blender camera object)"),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn paper_camera() -> Camera {
        Camera::top_down(1920, 1080, 50.0, 36.0, Vec3::new(0.0, 0.0, 1.0))
    }

    #[test]
    fn blender_default_camera_intrinsics() {
        let cam = paper_camera();
        assert!((cam.fx - 50.0 / 36.0 * 1920.0).abs() < 1e-9);
        assert_eq!((cam.cx, cam.cy), (959.5, 539.5));
        // At 1 m the frame covers 36/50 m across.
        let fp = cam.footprint(0.0);
        assert!((fp.x1 - fp.x0 - 0.72).abs() < 1e-12 && (fp.y1 - fp.y0 - 0.72 * 1080.0 / 1920.0).abs() < 1e-12);
    }

    #[test]
    fn projection_and_rays_agree_and_image_axes_match_the_world() {
        let cam = paper_camera();
        let p = Vec3::new(0.1, 0.05, 0.02);
        let (u, v, z) = cam.project(p);
        assert!(u > cam.cx && v < cam.cy, "world +x is image right, world +y is image up");
        assert!((z - 0.98).abs() < 1e-12);
        let back = cam.position + cam.ray_direction(u, v) * z;
        assert!((back - p).length() < 1e-12);
    }

    #[test]
    fn crops_shift_the_principal_point() {
        let cam = paper_camera();
        let crop = cam.crop(448, 28, 1024, 1024).crop(10, 20, 100, 100);
        let p = Vec3::new(-0.03, 0.07, 0.01);
        let (u, v, _) = cam.project(p);
        let (cu, cv, _) = crop.project(p);
        assert!((u - 458.0 - cu).abs() < 1e-9 && (v - 48.0 - cv).abs() < 1e-9);
        assert_eq!(crop.crop_offset, (458, 48));
    }
}
