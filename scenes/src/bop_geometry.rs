//! Where BOP's objects and cameras are: world-to-camera poses inverted, and what a BOP dataset
//! says of its objects' models: `models/models_info.json` at the dataset's
//! root (beside the split folder, `lm/models/` for `lm/train_pbr/`), each obj_id's
//! axis-aligned box in its model's frame (`min_x`, `min_y`, `min_z`, `size_x`, `size_y`,
//! `size_z`, millimetres; `diameter` and the symmetries are left alone). With it each gt gets
//! its `bbox_3d`, and its category the box's keypoints.

use crate::SceneError;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use vkdiff_render::camera::Pose;
use vkdiff_render::geometry::Box3;

pub const MODELS_INFO: &str = "models/models_info.json";

#[derive(Deserialize)]
struct ModelInfo {
    min_x: f64,
    min_y: f64,
    min_z: f64,
    size_x: f64,
    size_y: f64,
    size_z: f64,
}

/// Where models_info.json is for the scenes of `dir` (a split folder, or one scene folder):
/// the dataset root above it, or `dir` itself where it holds `models/`.
pub fn models_info_path(dir: &Path, one_scene: bool) -> Option<PathBuf> {
    let up = if one_scene { 2 } else { 1 };
    let root = dir.ancestors().nth(up);
    [Some(dir), root].into_iter().flatten().map(|d| d.join(MODELS_INFO)).find(|p| p.is_file())
}

/// Each obj_id's box, metres.
pub fn read_models_info(path: &Path) -> Result<BTreeMap<u32, Box3>, SceneError> {
    let refuse = |why: String| SceneError::new(format!("{}: {why}", path.display()));
    let text = std::fs::read_to_string(path).map_err(|e| refuse(e.to_string()))?;
    let models: BTreeMap<String, ModelInfo> =
        serde_json::from_str(&text).map_err(|e| refuse(format!("not BOP's models_info: {e}")))?;
    models
        .into_iter()
        .map(|(key, m)| {
            let id: u32 = key.parse().map_err(|_| refuse(format!("key `{key}` is not an obj_id")))?;
            let min = [m.min_x, m.min_y, m.min_z];
            let size = [m.size_x, m.size_y, m.size_z];
            if min.iter().chain(&size).any(|v| !v.is_finite()) || size.iter().any(|&s| s < 0.0) {
                return Err(refuse(format!("obj_id {id}: its box is not finite with sizes ≥ 0")));
            }
            let metres = |v: f64| v / 1000.0;
            let bbox = Box3 { min: min.map(metres), max: std::array::from_fn(|i| metres(min[i] + size[i])) };
            Ok((id, bbox))
        })
        .collect()
}

/// T_world_camera (metres) from BOP's world-to-camera rotation and translation (mm).
pub fn world_from_camera(r: &[f64], t: &[f64]) -> Result<Pose, String> {
    let (&[r00, r01, r02, r10, r11, r12, r20, r21, r22], &[t0, t1, t2]) = (r, t) else {
        return Err("cam_R_w2c holds 9 values and cam_t_w2c 3".into());
    };
    // The inverse of [R | t]: [Rᵀ | −Rᵀt], millimetres to metres.
    let rt = [[r00, r10, r20], [r01, r11, r21], [r02, r12, r22]];
    let centre = |row: [f64; 3]| -(row[0] * t0 + row[1] * t1 + row[2] * t2) / 1000.0;
    let row = |k: usize| [rt[k][0], rt[k][1], rt[k][2], centre(rt[k])];
    Ok(Pose::Given([row(0), row(1), row(2), [0.0, 0.0, 0.0, 1.0]]))
}
