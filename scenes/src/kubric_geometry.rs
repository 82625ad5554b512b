//! Kubric's geometry in OpenCV's terms, as its code writes it into metadata.json
//! (google-research/kubric at 0ee21e2a, the same as PyPI's kubric-nightly 2023.12.27):
//!
//! - Quaternions are (w, x, y, z), pyquaternion's order (kubric/core/objects.py: Object3D's
//!   `quaternion`, `rotation_matrix` = pyquaternion.Quaternion(*q).rotation_matrix), each
//!   object's rotation into the world; written as float32 (Asset.get_values_over_time), so
//!   normalised here. The world is Blender's: right-handed, z up, metres.
//! - The camera's frame is Blender's (x right, y up, looking along −z); OpenCV's is x right,
//!   y down, z forward, so camera → world in OpenCV's axes is R·diag(1, −1, −1) with the
//!   camera's position: `T_world_camera_opencv` maps into Kubric's world as it is.
//! - `K` (kubric/core/cameras.py, PerspectiveCamera.intrinsics) is in normalised image units
//!   (width = height = 1) and for Blender's camera axes: [[f/sw, 0, −½], [0, −f/sh, −½],
//!   [0, 0, −1]] with sh = sw·H/W (Blender's sensor_fit HORIZONTAL, which kubric's renderer sets):
//!   K·(X, Y, Z) / −Z is the point's position in [0, 1]² from the image's top-left corner. In
//!   OpenCV's axes that is K·diag(1, −1, −1); scaled by W and H and moved to pixel centres:
//!   fx = K00·W, fy = −K11·H, cx = −K02·W − ½, cy = −K12·H − ½.
//! - `depth_NNNNN.tiff` is the distance along the ray (blender_utils.process_depth:
//!   camera.z_to_depth of Blender's Z pass, z·sqrt(1 + (x² + y²)/f²) at each pixel centre on the
//!   sensor): made planar here with K, z = d / |((u − cx)/fx, (v − cy)/fy, 1)|.
//! - `normal_NNNNN.png` is Blender's Normal pass, world space (blender_utils.process_normal:
//!   uint16 (n + 1)·65535/2; the background, n = 0, is 32767): turned into the camera's frame
//!   with the frame's camera rotation.
//! - An instance's `positions`, `quaternions` and `bboxes_3d` (kubric/utils.py,
//!   get_instance_info): per frame, the object's frame in the world, and the eight world corners
//!   of its bounds × scale (PhysicalObject.bbox_3d: the product of the bounds' min and max per
//!   axis, turned and moved). `pose` is the object's frame to the camera's (OpenCV),
//!   X_cam = R·X_obj + t; `bbox_3d` the corners taken back into the object's frame: its
//!   bounds × scale.

use vkdiff_render::geometry::{Box3, ObjectPose};

pub type Matrix = [[f64; 3]; 3];

/// A quaternion (w, x, y, z) as a rotation matrix; one far from length 1 is refused (float32's
/// rounding is normalised away).
pub fn rotation_of(q: [f64; 4]) -> Result<Matrix, String> {
    let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    if !norm.is_finite() || (norm - 1.0).abs() > 1e-3 {
        return Err(format!("quaternion {q:?} is not a unit quaternion (w, x, y, z)"));
    }
    let [w, x, y, z] = q.map(|v| v / norm);
    Ok([
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w)],
        [2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w)],
        [2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y)],
    ])
}

fn transpose(r: &Matrix) -> Matrix {
    std::array::from_fn(|i| std::array::from_fn(|j| r[j][i]))
}

fn mul(a: &Matrix, b: &Matrix) -> Matrix {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

fn apply(r: &Matrix, v: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| (0..3).map(|k| r[i][k] * v[k]).sum())
}

fn finite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// fx, fy, cx, cy (OpenCV pixels) of a `width`×`height` frame from Kubric's normalised `K`; a K
/// that is not a pinhole's in Kubric's form (an OrthographicCamera's, skew, a last row other than
/// (0, 0, −1)) is refused.
pub fn intrinsics(k: &Matrix, width: u32, height: u32) -> Result<[f64; 4], String> {
    let kubric_form = k[0][1] == 0.0 && k[1][0] == 0.0 && k[2][0] == 0.0 && k[2][1] == 0.0 && k[2][2] == -1.0;
    let (fx, fy) = (k[0][0] * width as f64, -k[1][1] * height as f64);
    if !kubric_form || !finite(&k.concat()) || fx <= 0.0 || fy <= 0.0 {
        return Err(format!(
            "K {k:?} is not a perspective camera's as Kubric writes it ([[f/sw, 0, −½], [0, −f/sh, −½], [0, 0, −1]])"
        ));
    }
    Ok([fx, fy, -k[0][2] * width as f64 - 0.5, -k[1][2] * height as f64 - 0.5])
}

/// The camera's pose, camera → world in OpenCV's camera axes, and its rotation alone.
pub fn camera_pose(position: [f64; 3], quaternion: [f64; 4]) -> Result<([[f64; 4]; 4], Matrix), String> {
    if !finite(&position) {
        return Err(format!("position {position:?} is not finite"));
    }
    let r = rotation_of(quaternion)?;
    // Blender's camera axes to OpenCV's: y and z negated (+ 0.0: no −0.0 written).
    let cv: Matrix = std::array::from_fn(|i| std::array::from_fn(|j| if j == 0 { r[i][j] } else { -r[i][j] } + 0.0));
    let row = |i: usize| [cv[i][0], cv[i][1], cv[i][2], position[i]];
    Ok(([row(0), row(1), row(2), [0.0, 0.0, 0.0, 1.0]], cv))
}

/// An instance's pose in the camera (`camera`: camera → world rotation in OpenCV's axes, and
/// the camera's position) and its box in its own frame, from its world position, quaternion and
/// the eight world corners of its box. Corners that are not a box along the object's axes
/// (another quaternion convention, say) are refused.
pub fn instance_pose(
    camera: (&Matrix, [f64; 3]),
    position: [f64; 3],
    quaternion: [f64; 4],
    corners: &[[f64; 3]; 8],
) -> Result<(ObjectPose, Box3), String> {
    if !finite(&position) || !finite(&corners.concat()) {
        return Err("its position and bboxes_3d must be finite".into());
    }
    let r = rotation_of(quaternion)?;
    let back = transpose(&r);
    let local: Vec<[f64; 3]> =
        corners.iter().map(|c| apply(&back, std::array::from_fn(|i| c[i] - position[i]))).collect();
    let min: [f64; 3] = std::array::from_fn(|i| local.iter().map(|c| c[i]).fold(f64::INFINITY, f64::min));
    let max: [f64; 3] = std::array::from_fn(|i| local.iter().map(|c| c[i]).fold(f64::NEG_INFINITY, f64::max));
    let scale = 1.0 + (0..3).map(|i| max[i] - min[i]).fold(0.0, f64::max);
    let tolerance = 1e-4 * scale;
    let on_a_corner =
        local.iter().all(|c| (0..3).all(|i| (c[i] - min[i]).abs().min((c[i] - max[i]).abs()) <= tolerance));
    if !on_a_corner {
        return Err(format!(
            "its bboxes_3d corners, taken into its frame (quaternion (w, x, y, z) at its position), are not a \
             box along its axes: {local:?}"
        ));
    }
    let (cv, eye) = camera;
    let to_camera = transpose(cv);
    let t = apply(&to_camera, std::array::from_fn(|i| position[i] - eye[i]));
    Ok((ObjectPose { r: mul(&to_camera, &r), t }, Box3 { min, max }))
}

/// Distance along the ray to planar depth along the camera's axis, through K:
/// z = d / |((u − cx)/fx, (v − cy)/fy, 1)|.
pub fn planar_from_distance(distance: &mut [f32], width: usize, [fx, fy, cx, cy]: [f64; 4]) {
    for (p, d) in distance.iter_mut().enumerate() {
        let (x, y) = (((p % width) as f64 - cx) / fx, ((p / width) as f64 - cy) / fy);
        *d = (*d as f64 / (x * x + y * y + 1.0).sqrt()) as f32;
    }
}

/// A pixel of Kubric's normal PNG (each component (n + 1)·max/2, world space) in the camera's
/// frame, OpenCV's axes (`camera`: camera → world in those axes); zero where nothing was hit
/// (Blender's pass is 0 there, written as the middle value).
pub fn decode_normal(rgb: [u16; 3], max: f64, camera: &Matrix) -> [f32; 3] {
    let world = rgb.map(|v| 2.0 * v as f64 / max - 1.0);
    if world.iter().map(|c| c * c).sum::<f64>() < 0.25 {
        return [0.0; 3];
    }
    apply(&transpose(camera), world).map(|c| c as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quaternions_are_w_first() {
        // 90° about z: x → y.
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let r = rotation_of([h, 0.0, 0.0, h]).unwrap();
        let v = apply(&r, [1.0, 0.0, 0.0]);
        assert!((v[0]).abs() < 1e-12 && (v[1] - 1.0).abs() < 1e-12, "{v:?}");
        assert!(rotation_of([0.5, 0.0, 0.0, 0.0]).unwrap_err().contains("not a unit quaternion"));
    }

    #[test]
    fn k_in_pixels() {
        // focal 35, sensor 32, 48×40: f/sw = 1.09375, f/sh = 1.3125.
        let k = [[1.09375, 0.0, -0.5], [0.0, -1.3125, -0.5], [0.0, 0.0, -1.0]];
        assert_eq!(intrinsics(&k, 48, 40).unwrap(), [52.5, 52.5, 23.5, 19.5]);
        let orthographic = [[0.33, 0.0, 0.0], [0.0, 0.33, 0.0], [0.0, 0.0, -1.0]];
        assert!(intrinsics(&orthographic, 48, 40).unwrap_err().contains("not a perspective camera's"));
    }

    #[test]
    fn the_identity_camera_looks_down_minus_z() {
        // Kubric's camera at rest looks along the world's −z with y up: OpenCV's z is −z, y is −y.
        let (t, cv) = camera_pose([1.0, 2.0, 3.0], [1.0, 0.0, 0.0, 0.0]).unwrap();
        assert_eq!(cv, [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]);
        assert_eq!(t[2][3], 3.0);
        // A box 2 m below the camera, not turned: 2 m ahead in OpenCV's camera.
        let corners: [[f64; 3]; 8] = std::array::from_fn(|k| {
            [1.0 + [-0.5, 0.5][k >> 2], 2.0 + [-0.25, 0.25][(k >> 1) & 1], 1.0 + [-0.125, 0.125][k & 1]]
        });
        let (pose, bbox) =
            instance_pose((&cv, [1.0, 2.0, 3.0]), [1.0, 2.0, 1.0], [1.0, 0.0, 0.0, 0.0], &corners).unwrap();
        assert_eq!(pose.t, [0.0, 0.0, 2.0]);
        assert_eq!(bbox, Box3 { min: [-0.5, -0.25, -0.125], max: [0.5, 0.25, 0.125] });
        // The same corners said to be turned 30° about z: not a box along those axes.
        let (c, s) = (15f64.to_radians().cos(), 15f64.to_radians().sin());
        let turned = instance_pose((&cv, [1.0, 2.0, 3.0]), [1.0, 2.0, 1.0], [c, 0.0, 0.0, s], &corners);
        assert!(turned.unwrap_err().contains("not a box along its axes"));
    }

    #[test]
    fn background_normals_are_unknown() {
        let eye: Matrix = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]];
        assert_eq!(decode_normal([32767; 3], 65535.0, &eye), [0.0; 3]);
        // World up, camera at rest (looking down): toward the camera, OpenCV's −z.
        assert_eq!(decode_normal([32767, 32767, 65535], 65535.0, &eye)[2] as f64, -1.0);
    }
}
