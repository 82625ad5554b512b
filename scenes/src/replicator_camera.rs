//! The camera of Replicator BasicWriter's camera_params_N.json. USD writes matrices in the
//! row-vector convention (a point is a row, p' = p·M, the translation in the last row), on USD's
//! camera axes (x right, y up, looking along −z).

use serde::Deserialize;
use vkdiff_render::camera::Pose;

/// camera_params_N.json, the fields read (the lens fields are left alone).
#[derive(Deserialize)]
#[serde(rename_all = "camelCase")]
pub(crate) struct CameraParams {
    camera_projection: Vec<f64>,
    camera_view_transform: Option<Vec<f64>>,
    pub render_product_resolution: [u32; 2],
    camera_model: Option<String>,
    pub meters_per_scene_unit: Option<f64>,
}

/// The view transform as a column-vector map, world → camera (USD's axes, scene units):
/// camera = r·world + t.
#[derive(Clone, Debug)]
pub(crate) struct View {
    pub r: [[f64; 3]; 3],
    pub t: [f64; 3],
}

impl View {
    /// The camera's pose in the world, in OpenCV's camera axes, metres.
    pub fn world_from_camera(&self, metres_per_unit: f64) -> Pose {
        let (r, t) = (&self.r, &self.t);
        // [Rᵀ | −Rᵀt]; USD's camera axes to OpenCV's (y and z turned: columns 1 and 2 negated).
        let centre = |j: usize| -(0..3).map(|k| r[k][j] * t[k]).sum::<f64>() * metres_per_unit;
        let row = |j: usize| [r[0][j], -r[1][j], -r[2][j], centre(j)];
        Pose::Given([row(0), row(1), row(2), [0.0, 0.0, 0.0, 1.0]])
    }
}

/// fx, fy, cx, cy from camera_params: None where the camera is not a pinhole (a fisheye model, an
/// orthographic or skewed projection).
pub(crate) fn intrinsics_of(p: &CameraParams) -> Result<Option<[f64; 4]>, String> {
    let [w, h] = p.render_product_resolution;
    if w == 0 || h == 0 {
        return Err(format!("renderProductResolution [{w}, {h}] is empty"));
    }
    let &[p00, p01, p02, p03, p10, p11, p12, p13, p20, p21, _, p23, _, _, _, p33] = &p.camera_projection[..] else {
        return Err(format!("cameraProjection has {} values, not 16 (4×4)", p.camera_projection.len()));
    };
    let pinhole = p.camera_model.as_deref().is_none_or(|m| m == "pinhole")
        && [p01, p02, p03, p10, p12, p13, p33] == [0.0; 7]
        && p23 == -1.0
        && p00 > 0.0
        && p11 > 0.0;
    // A point in the camera's USD axes goes to clip space as [x y z 1]·P, then NDC [−1, 1] spans
    // the image's pixel edges, y up. In OpenCV's axes and pixel centres:
    let (w, h) = (w as f64, h as f64);
    Ok(pinhole.then(|| [p00 * w / 2.0, p11 * h / 2.0, w / 2.0 * (1.0 - p20) - 0.5, h / 2.0 * (1.0 + p21) - 0.5]))
}

/// The view transform, where camera_params gives one; one that is not a rotation and a
/// translation is refused.
pub(crate) fn view_of(p: &CameraParams) -> Result<Option<View>, String> {
    let Some(view) = &p.camera_view_transform else {
        return Ok(None);
    };
    let &[v00, v01, v02, v03, v10, v11, v12, v13, v20, v21, v22, v23, v30, v31, v32, v33] = &view[..] else {
        return Err(format!("cameraViewTransform has {} values, not 16 (4×4)", view.len()));
    };
    if [v03, v13, v23, v33] != [0.0, 0.0, 0.0, 1.0] {
        return Err("cameraViewTransform's last column is not [0, 0, 0, 1] (row-vector convention)".into());
    }
    // camera = world · V: the rotation world → camera is Vᵀ's 3×3, its translation V's last row.
    let r = [[v00, v10, v20], [v01, v11, v21], [v02, v12, v22]];
    if !orthonormal(&r) {
        return Err("cameraViewTransform is not a rotation and a translation".into());
    }
    Ok(Some(View { r, t: [v30, v31, v32] }))
}

pub(crate) fn dot(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(crate) fn orthonormal(rows: &[[f64; 3]; 3]) -> bool {
    (0..3).all(|i| (0..3).all(|j| (dot(&rows[i], &rows[j]) - if i == j { 1.0 } else { 0.0 }).abs() <= 1e-4))
}
