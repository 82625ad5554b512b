//! Unity's geometry in OpenCV's terms, as com.unity.perception 1.0 writes it into SOLO's
//! frame_data.json (Unity-Technologies/com.unity.perception at 7e3d4c95, Runtime/GroundTruth):
//!
//! - Frames. Unity's camera transform (and every object's, and the world) is left-handed: x right,
//!   y up, z forward. OpenCV's camera is x right, y down, z forward. Every Unity frame is taken to
//!   OpenCV's by negating its y axis, S = diag(1, −1, 1): a point p becomes S·p and a rotation R
//!   becomes S·R·S (a proper rotation again). The world too: `T_world_camera_opencv` maps into
//!   Unity's world with y negated (x, −y, z of Unity's world coordinates).
//! - Quaternions are written x, y, z, w (MessageBuilderUtils.ToFloatVector(Quaternion)), as Unity's
//!   Quaternion * Vector3 rotates (the usual Hamilton rotation).
//! - The capture's `matrix` is the upper-left 3×3 of Camera.projectionMatrix (OpenGL's convention:
//!   view space x right, y up, looking along −z; NDC [−1, 1] spanning the pixel edges, y up),
//!   written column by column (SoloMessageBuilder.AddTensor: c0.x, c0.y, c0.z, c1.x, …), so
//!   m = [P00, P10, P20, P01, P11, P21, P02, P12, P22]. A point at depth d in front of the camera,
//!   (x, y) in the transform's frame, lands at NDC (P00·x/d − P02, P11·y/d − P12), which in OpenCV's
//!   pixel centres of a W×H image is fx = P00·W/2, fy = P11·H/2, cx = W/2·(1 − P02) − ½,
//!   cy = H/2·(1 + P12) − ½.
//! - BoundingBox3DAnnotation: `translation` is the centre of the object's mesh bounds in the
//!   camera transform's frame, `rotation` the object's rotation in that frame, `size` the bounds'
//!   size (× the object's scale) along the object's own axes. The box's own frame (its centre, the
//!   object's axes) is the frame `pose` maps from: X_cam = R·X_box + t, R = S·R_unity·S,
//!   t = S·translation; `bbox_3d` is ±size/2 about its origin.

use serde::Deserialize;
use vkdiff_render::camera::Pose;
use vkdiff_render::geometry::{Box3, ObjectPose};

type Matrix = [[f64; 3]; 3];

/// A unit quaternion (x, y, z, w) as a rotation matrix; one not of length 1 is refused.
pub fn rotation_of(q: [f64; 4]) -> Result<Matrix, String> {
    let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    if !norm.is_finite() || (norm - 1.0).abs() > 1e-3 {
        return Err(format!("rotation {q:?} is not a unit quaternion (x, y, z, w)"));
    }
    let [x, y, z, w] = q.map(|v| v / norm);
    Ok([
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w)],
        [2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w)],
        [2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y)],
    ])
}

/// y negated: Unity's axes to OpenCV's.
const S: [f64; 3] = [1.0, -1.0, 1.0];

/// A rotation between Unity frames as one between their OpenCV counterparts: S·R·S (+ 0.0: no
/// −0.0 written).
pub fn flip_rotation(r: Matrix) -> Matrix {
    std::array::from_fn(|i| std::array::from_fn(|j| r[i][j] * S[i] * S[j] + 0.0))
}

/// A point of a Unity frame in its OpenCV counterpart: S·p.
pub fn flip_point(p: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| p[i] * S[i] + 0.0)
}

/// One value of a BoundingBox3DAnnotation (velocity and acceleration are not read).
#[derive(Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Box3DValue {
    pub instance_id: i64,
    pub translation: [f64; 3],
    pub size: [f64; 3],
    pub rotation: [f64; 4],
}

/// The box's pose (box frame → OpenCV camera, metres) and its extent about its own origin.
pub fn box_pose(value: &Box3DValue) -> Result<(ObjectPose, Box3), String> {
    let (t, size) = (value.translation, value.size);
    if t.iter().any(|v| !v.is_finite()) || size.iter().any(|s| !(s.is_finite() && *s >= 0.0)) {
        return Err(format!("translation {t:?} and size {size:?} must be finite, the size ≥ 0"));
    }
    let r = flip_rotation(rotation_of(value.rotation)?);
    let bbox = Box3 { min: size.map(|s| -s / 2.0), max: size.map(|s| s / 2.0) };
    Ok((ObjectPose { r, t: flip_point(t) }, bbox))
}

/// A capture's camera, the fields read.
#[derive(Deserialize)]
pub struct CaptureCamera {
    pub position: Option<[f64; 3]>,
    pub rotation: Option<[f64; 4]>,
    pub projection: Option<String>,
    pub matrix: Option<Vec<f64>>,
}

/// fx, fy, cx, cy (OpenCV pixels) of a `width`×`height` capture and its pose; None where the
/// projection is not a perspective pinhole ("Isometric", "fisheye", or a matrix with skew), which
/// no K describes. A matrix that is not 3×3 or a rotation that is not a unit quaternion is refused.
pub fn camera_of(c: &CaptureCamera, width: u32, height: u32) -> Result<Option<([f64; 4], Pose)>, String> {
    let Some(matrix) = &c.matrix else { return Ok(None) };
    let &[p00, p10, p20, p01, p11, p21, p02, p12, _] = &matrix[..] else {
        return Err(format!("matrix has {} values, not 9 (3×3)", matrix.len()));
    };
    let perspective = c.projection.as_deref().is_some_and(|p| p.eq_ignore_ascii_case("perspective"));
    let pinhole = perspective
        && [p10, p20, p01, p21] == [0.0; 4]
        && p00 > 0.0
        && p11 > 0.0
        && p00.is_finite()
        && p11.is_finite()
        && p02.is_finite()
        && p12.is_finite();
    if !pinhole {
        return Ok(None);
    }
    let (w, h) = (width as f64, height as f64);
    let k = [p00 * w / 2.0, p11 * h / 2.0, w / 2.0 * (1.0 - p02) - 0.5, h / 2.0 * (1.0 + p12) - 0.5];
    let (Some(position), Some(rotation)) = (c.position, c.rotation) else {
        return Ok(Some((k, Pose::Unknown)));
    };
    if position.iter().any(|v| !v.is_finite()) {
        return Err(format!("position {position:?} is not finite"));
    }
    // Camera → Unity's world is [R | p]; in OpenCV's axes on both sides, [S·R·S | S·p].
    let r = flip_rotation(rotation_of(rotation)?);
    let t = flip_point(position);
    let row = |i: usize| [r[i][0], r[i][1], r[i][2], t[i]];
    Ok(Some((k, Pose::Given([row(0), row(1), row(2), [0.0, 0.0, 0.0, 1.0]]))))
}

/// Range (distance to the camera, DepthMeasurementStrategy.Range) to planar depth along the
/// camera's axis, through K: z = r / |(u − cx)/fx, (v − cy)/fy, 1|; 0 (nothing drawn) stays 0.
pub fn planar_from_range(range: &mut [f32], width: usize, [fx, fy, cx, cy]: [f64; 4]) {
    for (p, r) in range.iter_mut().enumerate() {
        let (u, v) = ((p % width) as f64, (p / width) as f64);
        let (x, y) = ((u - cx) / fx, (v - cy) / fy);
        *r = (*r as f64 / (x * x + y * y + 1.0).sqrt()) as f32;
    }
}

/// Unity's encoded normals (NormalLabeler: the camera-frame normal n, each component written
/// (c + 1) / 2, then z as 1 − z; (0, 0, 0) where nothing is drawn) in OpenCV's camera axes; zero
/// where unknown.
pub fn decode_normal([r, g, b]: [f32; 3]) -> [f32; 3] {
    if [r, g, b] == [0.0; 3] || ![r, g, b].iter().all(|v| v.is_finite()) {
        return [0.0; 3];
    }
    // Decoded: (nx, ny, −nz) in Unity's camera frame; OpenCV's is (nx, −ny, nz).
    let (x, y, minus_z) = (2.0 * r - 1.0, 2.0 * g - 1.0, 2.0 * b - 1.0);
    [x, -y, -minus_z]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quaternions_turn_as_unity_turns_them() {
        // 90° about y (Unity: x → −z, z → x).
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let r = rotation_of([0.0, h, 0.0, h]).unwrap();
        let apply = |v: [f64; 3]| -> [f64; 3] { std::array::from_fn(|i| (0..3).map(|j| r[i][j] * v[j]).sum()) };
        let close = |a: [f64; 3], b: [f64; 3]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12);
        assert!(close(apply([1.0, 0.0, 0.0]), [0.0, 0.0, -1.0]));
        assert!(close(apply([0.0, 0.0, 1.0]), [1.0, 0.0, 0.0]));
        assert!(rotation_of([0.0, 0.0, 0.0, 0.5]).unwrap_err().contains("not a unit quaternion"));
        // S·R·S is a rotation again: det 1.
        let f = flip_rotation(r);
        let det = f[0][0] * (f[1][1] * f[2][2] - f[1][2] * f[2][1]) - f[0][1] * (f[1][0] * f[2][2] - f[1][2] * f[2][0])
            + f[0][2] * (f[1][0] * f[2][1] - f[1][1] * f[2][0]);
        assert!((det - 1.0).abs() < 1e-12);
    }

    #[test]
    fn the_matrix_is_read_column_by_column() {
        // P02 = 0.2 (c2.x, the 7th value), P12 = −0.1 (c2.y, the 8th): 100×50 pixels.
        let c = CaptureCamera {
            position: None,
            rotation: None,
            projection: Some("Perspective".into()),
            matrix: Some(vec![1.5, 0.0, 0.0, 0.0, 2.0, 0.0, 0.2, -0.1, -1.0006]),
        };
        let (k, pose) = camera_of(&c, 100, 50).unwrap().unwrap();
        assert_eq!(k, [75.0, 50.0, 50.0 * 0.8 - 0.5, 25.0 * 0.9 - 0.5]);
        assert_eq!(pose, Pose::Unknown);
        let skewed = CaptureCamera { matrix: Some(vec![1.5, 0.0, 0.0, 0.1, 2.0, 0.0, 0.0, 0.0, -1.0]), ..c };
        assert_eq!(camera_of(&skewed, 100, 50).unwrap(), None);
        let isometric = CaptureCamera {
            projection: Some("Isometric".into()),
            matrix: Some(vec![0.2, 0.0, 0.0, 0.0, 0.2, 0.0, 0.0, 0.0, -0.002]),
            ..skewed
        };
        assert_eq!(camera_of(&isometric, 100, 50).unwrap(), None);
        let short = CaptureCamera { projection: Some("Perspective".into()), matrix: Some(vec![1.0; 4]), ..isometric };
        assert!(camera_of(&short, 100, 50).unwrap_err().contains("4 values, not 9"));
    }

    #[test]
    fn normals_decode_to_opencv_axes() {
        // Facing the camera: Unity's n = (0, 0, −1), written (0.5, 0.5, 1 − 0) = (0.5, 0.5, 1).
        assert_eq!(decode_normal([0.5, 0.5, 1.0]), [0.0, 0.0, -1.0]);
        // Up: Unity's (0, 1, 0) → (0.5, 1, 0.5); OpenCV's y is down.
        assert_eq!(decode_normal([0.5, 1.0, 0.5]), [0.0, -1.0, 0.0]);
        assert_eq!(decode_normal([0.0, 0.0, 0.0]), [0.0; 3]);
    }
}
