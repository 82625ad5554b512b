//! A Kubric sequence's metadata.json (kubric.rs), parsed and checked: the frame counts, K, and the
//! camera's and the instances' poses per frame.

use crate::kubric_geometry::{camera_pose, instance_pose, intrinsics, Matrix};
use crate::SceneError;
use serde::Deserialize;
use std::path::{Path, PathBuf};
use vkdiff_render::geometry::{Box3, ObjectPose};

pub(crate) const METADATA: &str = "metadata.json";

#[derive(Deserialize)]
struct MetadataFile {
    metadata: SceneMetadata,
    camera: CameraMetadata,
    #[serde(default)]
    instances: Vec<InstanceMetadata>,
}

#[derive(Deserialize)]
struct SceneMetadata {
    resolution: [u32; 2],
    num_frames: usize,
}

#[derive(Deserialize)]
struct CameraMetadata {
    #[serde(rename = "K")]
    k: Matrix,
    positions: Vec<[f64; 3]>,
    quaternions: Vec<[f64; 4]>,
}

#[derive(Deserialize)]
struct InstanceMetadata {
    asset_id: Option<String>,
    category: Option<String>,
    positions: Option<Vec<[f64; 3]>>,
    quaternions: Option<Vec<[f64; 4]>>,
    bboxes_3d: Option<Vec<[[f64; 3]; 8]>>,
}

/// One instance of a sequence: segmentation index `index`.
#[derive(Debug)]
pub(crate) struct KubricInstance {
    pub(crate) index: u32,
    pub(crate) category: String,
    pub(crate) asset_id: Option<String>,
    /// Per frame, its pose in the camera and its box, where metadata.json gives them.
    pub(crate) boxes: Vec<Option<(ObjectPose, Box3)>>,
}

/// One Kubric output folder, its metadata.json parsed.
#[derive(Debug)]
pub(crate) struct Sequence {
    pub(crate) name: String,
    pub(crate) folder: PathBuf,
    pub(crate) width: u32,
    pub(crate) height: u32,
    /// fx, fy, cx, cy in pixels.
    pub(crate) k: [f64; 4],
    /// Per frame: camera → world (OpenCV's camera axes) and its rotation.
    pub(crate) poses: Vec<([[f64; 4]; 4], Matrix)>,
    pub(crate) instances: Vec<KubricInstance>,
}

/// A sequence's name: its folder's.
pub(crate) fn name_of(folder: &Path) -> String {
    folder.file_name().map_or(folder.display().to_string(), |n| n.to_string_lossy().into_owned())
}

/// A sequence's metadata.json, checked: frame counts, K, the camera's and instances' poses.
pub(crate) fn parse_sequence(folder: &Path, default_category: &str) -> Result<Sequence, SceneError> {
    let name = name_of(folder);
    let fail = |why: String| SceneError::new(format!("{name}: {METADATA}: {why}"));
    let text = std::fs::read_to_string(folder.join(METADATA)).map_err(|e| fail(e.to_string()))?;
    let data: MetadataFile = serde_json::from_str(&text).map_err(|e| fail(format!("not Kubric's metadata: {e}")))?;
    let [width, height] = data.metadata.resolution;
    let frames = data.metadata.num_frames;
    if width == 0 || height == 0 || frames == 0 {
        return Err(fail(format!("resolution [{width}, {height}] and num_frames {frames} must be positive")));
    }
    let counted = |what: &str, n: usize| -> Result<(), SceneError> {
        if n == frames {
            return Ok(());
        }
        Err(fail(format!("{what} has {n} frames, metadata.num_frames says {frames}")))
    };
    let camera = &data.camera;
    counted("camera.positions", camera.positions.len())?;
    counted("camera.quaternions", camera.quaternions.len())?;
    let k = intrinsics(&camera.k, width, height).map_err(|why| fail(format!("camera: {why}")))?;
    let poses = (0..frames)
        .map(|f| camera_pose(camera.positions[f], camera.quaternions[f]))
        .collect::<Result<Vec<_>, String>>()
        .map_err(|why| fail(format!("camera: {why}")))?;
    let mut instances = Vec::new();
    for (k0, i) in data.instances.into_iter().enumerate() {
        let index = k0 as u32 + 1;
        let what = format!("instance {index}{}", i.asset_id.as_ref().map_or(String::new(), |a| format!(" ({a})")));
        let category = match (&i.category, &i.asset_id) {
            (Some(c), _) if !c.trim().is_empty() => c.trim().to_string(),
            (None, Some(a)) if !a.trim().is_empty() => a.trim().to_string(),
            (None, None) => default_category.to_string(),
            _ => return Err(fail(format!("{what}: its category (or asset_id) is empty"))),
        };
        let mut boxes = vec![None; frames];
        if let (Some(positions), Some(quaternions), Some(corners)) = (&i.positions, &i.quaternions, &i.bboxes_3d) {
            counted(&format!("{what}: positions"), positions.len())?;
            counted(&format!("{what}: quaternions"), quaternions.len())?;
            counted(&format!("{what}: bboxes_3d"), corners.len())?;
            for (f, slot) in boxes.iter_mut().enumerate() {
                let (t, cv) = &poses[f];
                let eye = [t[0][3], t[1][3], t[2][3]];
                let pose = instance_pose((cv, eye), positions[f], quaternions[f], &corners[f])
                    .map_err(|why| fail(format!("{what}, frame {f}: {why}")))?;
                *slot = Some(pose);
            }
        }
        instances.push(KubricInstance { index, category, asset_id: i.asset_id, boxes });
    }
    Ok(Sequence { name, folder: folder.to_path_buf(), width, height, k, poses, instances })
}
