//! A scene folder's optional geometric files: camera.json (as `vkdiff scene` writes it: `K`,
//! `width`, `height`, and `T_world_camera_opencv` where the pose is known) and keypoints.json
//! (each instance's keypoints as COCO lists them: {"<instance>": [x1, y1, v1, x2, y2, v2, …]},
//! pixel centres at integers, v 0/1/2; their names come from the category in categories.json).

use crate::SceneError;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;
use vkdiff_render::camera::{Camera, Pose};
use vkdiff_render::coco::Category;
use vkdiff_render::geometry::Keypoint;

pub const CAMERA: &str = "camera.json";
pub const KEYPOINTS: &str = "keypoints.json";

#[derive(Deserialize)]
struct CameraFile {
    #[serde(rename = "K")]
    k: [[f64; 3]; 3],
    width: u32,
    height: u32,
    #[serde(default, rename = "T_world_camera_opencv")]
    pose: Option<PoseMatrix>,
}

#[derive(Deserialize)]
struct PoseMatrix {
    matrix: [[f64; 4]; 4],
}

/// camera.json's camera, checked against the depth's `size`; None without the file.
pub fn read_camera(dir: &Path, size: (usize, usize)) -> Result<Option<Camera>, SceneError> {
    let path = dir.join(CAMERA);
    if !path.is_file() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&path).map_err(|e| SceneError::io(&path, e))?;
    let file: CameraFile = serde_json::from_str(&text)
        .map_err(|e| SceneError::file(&path, format!("not a camera (K, width, height): {e}")))?;
    let [[fx, s, cx], [z0, fy, cy], [z1, z2, one]] = file.k;
    if [s, z0, z1, z2] != [0.0; 4] || one != 1.0 || !(fx > 0.0 && fy > 0.0) || !(cx.is_finite() && cy.is_finite()) {
        return Err(SceneError::file(&path, format!("K {:?} is not [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]", file.k)));
    }
    if (file.width as usize, file.height as usize) != size {
        let why = format!("{}×{}, the depth is {}×{}", file.width, file.height, size.0, size.1);
        return Err(SceneError::file(&path, why));
    }
    let pose = file.pose.map_or(Pose::Unknown, |p| Pose::Given(p.matrix));
    Ok(Some(Camera::from_intrinsics(file.width, file.height, [fx, fy, cx, cy], pose)))
}

/// keypoints.json's keypoints by instance; empty without the file.
pub fn read_keypoints(dir: &Path) -> Result<BTreeMap<u32, Vec<Keypoint>>, SceneError> {
    let path = dir.join(KEYPOINTS);
    if !path.is_file() {
        return Ok(BTreeMap::new());
    }
    let text = std::fs::read_to_string(&path).map_err(|e| SceneError::io(&path, e))?;
    let listed: BTreeMap<String, Vec<f64>> = serde_json::from_str(&text)
        .map_err(|e| SceneError::file(&path, format!("not {{\"<instance>\": [x, y, v, …]}}: {e}")))?;
    let refuse = |instance: &str, why: &str| SceneError::file(&path, format!("instance {instance}: {why}"));
    listed
        .into_iter()
        .map(|(key, flat)| {
            let id: u32 = key.parse().map_err(|_| refuse(&key, "not an instance number"))?;
            if flat.len() % 3 != 0 {
                return Err(refuse(&key, "the list is not x, y, v triples"));
            }
            let points = flat
                .chunks(3)
                .map(|p| match p[2] {
                    v if (v == 1.0 || v == 2.0) && p[0].is_finite() && p[1].is_finite() => {
                        Ok(Keypoint { x: p[0], y: p[1], v: v as u8 })
                    }
                    0.0 => Ok(Keypoint::ABSENT),
                    _ => Err(refuse(&key, &format!("{p:?} is not x, y and a visibility of 0, 1 or 2"))),
                })
                .collect::<Result<_, _>>()?;
            Ok((id, points))
        })
        .collect()
}

/// Refuses keypoints listed for an instance other than its category names (by `category_of`).
pub fn check_keypoint_counts<'a>(
    dir: &Path,
    keypoints: &BTreeMap<u32, Vec<Keypoint>>,
    category_of: impl Fn(u32) -> Option<&'a Category>,
) -> Result<(), SceneError> {
    for (&id, points) in keypoints {
        let names = category_of(id).map_or(0, |c| c.keypoints.len());
        if points.len() != names {
            let category = category_of(id).map_or("no category".to_string(), |c| format!("category `{}`", c.name));
            let why =
                format!("instance {id}: {} keypoints; its {category} names {names} in categories.json", points.len());
            return Err(SceneError::file(&dir.join(KEYPOINTS), why));
        }
    }
    Ok(())
}
