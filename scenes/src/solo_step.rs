//! One step of a SOLO sequence (solo.rs): its frame_data.json's captures read as scenes, every
//! file they name checked to be there, and an instance segmentation's colours.

use crate::solo_geometry::{box_pose, camera_of, Box3DValue, CaptureCamera};
use crate::SceneError;
use serde::Deserialize;
use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use vkdiff_render::camera::Pose;
use vkdiff_render::geometry::{Box3, ObjectPose};

pub(crate) const FRAME_DATA: &str = "frame_data.json";
const SOLO: &str = "type.unity.com/unity.solo.";
pub(crate) const INSTANCES: &str = "InstanceSegmentationAnnotation";
const DEPTH: &str = "DepthAnnotation";
const NORMALS: &str = "NormalAnnotation";
const BOXES: &str = "BoundingBox3DAnnotation";
/// The colours of instance index 0 (LabelManager's instanceSegmentationColors[0]) and of nothing
/// drawn at all; InstanceIdToColorMapping reads both as no instance.
pub(crate) const BACKGROUND: [[u8; 4]; 2] = [[0, 0, 0, 255], [0, 0, 0, 0]];

/// `why`, about `file` of scene `scene`, before the scenes are listed.
fn refuse(scene: &str, file: &str, why: impl std::fmt::Display) -> SceneError {
    SceneError::new(format!("scene {scene}: {file}: {why}"))
}

#[derive(Deserialize)]
struct FrameData {
    #[serde(default)]
    captures: Vec<Value>,
}

/// A capture's or annotation's "@type" ("" where it has none).
fn kind_of(record: &Value) -> &str {
    record.get("@type").and_then(Value::as_str).unwrap_or_default()
}

/// A capture's or annotation's "filename": None where it is absent or null (a capture whose
/// image Unity was told not to save).
fn filename_of(record: &Value) -> Result<Option<String>, String> {
    match record.get("filename") {
        None | Some(Value::Null) => Ok(None),
        Some(Value::String(name)) => Ok(Some(name.clone())),
        Some(other) => Err(format!("\"filename\" {other} is not a file name")),
    }
}

#[derive(Deserialize)]
#[serde(rename_all = "camelCase")]
struct InstanceEntry {
    instance_id: i64,
    label_id: i64,
    label_name: String,
    color: [u8; 4],
}

/// One instance of a scene.
#[derive(Clone, Debug)]
pub(crate) struct SoloInstance {
    pub(crate) id: u32,
    pub(crate) label_id: i64,
    pub(crate) label: String,
}

/// One capture with its instance segmentation: a scene.
#[derive(Debug)]
pub(crate) struct SoloScene {
    pub(crate) name: String,
    pub(crate) folder: PathBuf,
    pub(crate) rgb: Option<String>,
    /// The capture's `dimension`, W × H.
    pub(crate) dimension: (u32, u32),
    pub(crate) camera: Option<([f64; 4], Pose)>,
    pub(crate) instances: String,
    pub(crate) colours: BTreeMap<[u8; 4], SoloInstance>,
    pub(crate) depth: String,
    pub(crate) range: bool,
    pub(crate) normals: Option<String>,
    /// instanceId → its 3D box.
    pub(crate) boxes: BTreeMap<u32, (ObjectPose, Box3)>,
}

/// Step `step` of the sequence folder `folder` (named `seq`): its scenes, keyed.
pub(crate) fn parse_step(folder: &Path, seq: &str, step: u64) -> Result<Vec<(PathBuf, SoloScene)>, SceneError> {
    let step_name = format!("{seq}/step{step}");
    let data_name = format!("step{step}.{FRAME_DATA}");
    let text = std::fs::read_to_string(folder.join(&data_name)).map_err(|e| refuse(&step_name, &data_name, e))?;
    let data: FrameData = serde_json::from_str(&text)
        .map_err(|e| refuse(&step_name, &data_name, format!("not SOLO's frame data: {e}")))?;
    // Every file the step names must be there, whole.
    let named = |v: &Value| filename_of(v).map_err(|why| refuse(&step_name, &data_name, why));
    for capture in &data.captures {
        let annotations = capture.get("annotations").and_then(Value::as_array).map_or(&[][..], |a| &a[..]);
        for record in std::iter::once(capture).chain(annotations) {
            if let Some(name) = named(record)? {
                let why = match std::fs::metadata(folder.join(&name)) {
                    Ok(m) if m.is_file() && m.len() > 0 => continue,
                    Ok(m) if m.is_file() => "empty".to_string(),
                    _ => "missing".to_string(),
                };
                return Err(refuse(&step_name, &name, format!("{why} ({data_name} names it)")));
            }
        }
    }
    let mut scenes = Vec::new();
    for capture in &data.captures {
        let annotations = capture.get("annotations").and_then(Value::as_array).map_or(&[][..], |a| &a[..]);
        let of_kind = |kind: &str| -> Vec<&Value> {
            annotations.iter().filter(|a| kind_of(a).strip_prefix(SOLO) == Some(kind)).collect()
        };
        if of_kind(INSTANCES).is_empty() {
            continue;
        }
        scenes.push((capture, of_kind(INSTANCES), of_kind(DEPTH), of_kind(NORMALS), of_kind(BOXES)));
    }
    if scenes.is_empty() {
        let why = format!("no capture has an {INSTANCES} (an InstanceSegmentationLabeler on the Perception Camera)");
        return Err(refuse(&step_name, &data_name, why));
    }
    let several = scenes.len() > 1;
    let mut out = Vec::new();
    for (capture, instances, depth, normals, boxes) in scenes {
        let sensor = capture.get("id").and_then(Value::as_str).unwrap_or_default();
        let name = if several { format!("{step_name}.{sensor}") } else { step_name.clone() };
        let fail = |why: String| refuse(&name, &data_name, why);
        let one = |found: Vec<&Value>, kind: &str| -> Result<Option<Value>, SceneError> {
            match &found[..] {
                [] => Ok(None),
                [a] => Ok(Some((*a).clone())),
                _ => Err(fail(format!(
                    "capture `{sensor}` has {} {kind}s; one labeler of each kind is read",
                    found.len()
                ))),
            }
        };
        let instances = one(instances, INSTANCES)?.expect("a capture with an instance segmentation");
        let Some(depth) = one(depth, DEPTH)? else {
            return Err(fail(format!("capture `{sensor}` has no {DEPTH} (a DepthLabeler on the Perception Camera)")));
        };
        let normals = one(normals, NORMALS)?;
        let boxes = one(boxes, BOXES)?;
        let dimension = capture.get("dimension").cloned().and_then(|d| serde_json::from_value::<[f64; 2]>(d).ok());
        let dimension = match dimension {
            Some([w, h]) if w >= 1.0 && h >= 1.0 && w.fract() == 0.0 && h.fract() == 0.0 && w.max(h) < 1e6 => {
                (w as u32, h as u32)
            }
            _ => {
                let given = capture.get("dimension").map_or("none".to_string(), Value::to_string);
                return Err(fail(format!("capture `{sensor}`: dimension {given} is not [W, H] in pixels")));
            }
        };
        let camera_fields: CaptureCamera =
            serde_json::from_value(capture.clone()).map_err(|e| fail(format!("capture `{sensor}`: {e}")))?;
        let camera = camera_of(&camera_fields, dimension.0, dimension.1)
            .map_err(|why| fail(format!("capture `{sensor}`: {why}")))?;
        let file_of = |a: &Value, kind: &str| -> Result<String, SceneError> {
            named(a)?.ok_or_else(|| fail(format!("its {kind} names no file (\"filename\": null)")))
        };
        let colours = instance_colours(&instances).map_err(|why| fail(format!("{INSTANCES}: {why}")))?;
        let strategy = depth.get("measurementStrategy").and_then(Value::as_str).unwrap_or("Depth");
        let range = match strategy {
            "Depth" => false,
            "Range" => true,
            other => return Err(fail(format!("{DEPTH}: measurementStrategy `{other}` is neither Depth nor Range"))),
        };
        let mut by_instance = BTreeMap::new();
        if let Some(boxes) = &boxes {
            let values: Vec<Box3DValue> = match boxes.get("values") {
                Some(v) => serde_json::from_value(v.clone()).map_err(|e| fail(format!("{BOXES}: {e}")))?,
                None => Vec::new(),
            };
            for v in &values {
                let id =
                    u32::try_from(v.instance_id).map_err(|_| fail(format!("{BOXES}: instanceId {}", v.instance_id)))?;
                let pose = box_pose(v).map_err(|why| fail(format!("{BOXES}: instance {id}: {why}")))?;
                by_instance.insert(id, pose);
            }
        }
        let scene = SoloScene {
            name: name.clone(),
            folder: folder.to_path_buf(),
            rgb: named(capture)?,
            dimension,
            camera,
            instances: file_of(&instances, INSTANCES)?,
            colours,
            depth: file_of(&depth, DEPTH)?,
            range,
            normals: normals.as_ref().map(|n| file_of(n, NORMALS)).transpose()?,
            boxes: by_instance,
        };
        let key = folder.join(if several { format!("step{step}.{sensor}") } else { format!("step{step}") });
        out.push((key, scene));
    }
    Ok(out)
}

/// An InstanceSegmentationAnnotation's instances by colour; background colours, repeated colours
/// and instance ids are refused.
fn instance_colours(annotation: &Value) -> Result<BTreeMap<[u8; 4], SoloInstance>, String> {
    let entries: Vec<InstanceEntry> = match annotation.get("instances") {
        Some(v) => serde_json::from_value(v.clone()).map_err(|e| format!("instances: {e}"))?,
        None => Vec::new(),
    };
    let mut colours = BTreeMap::new();
    let mut ids = BTreeSet::new();
    for e in entries {
        let id = u32::try_from(e.instance_id).ok().filter(|&id| id > 0);
        let id = id.ok_or_else(|| format!("instanceId {} is not a positive 32-bit id", e.instance_id))?;
        if BACKGROUND.contains(&e.color) {
            return Err(format!("instance {id} has the background's colour {:?}", e.color));
        }
        if !ids.insert(id) {
            return Err(format!("instance {id} is listed twice"));
        }
        let label = e.label_name.trim().to_string();
        if label.is_empty() {
            return Err(format!("instance {id} has an empty labelName"));
        }
        let instance = SoloInstance { id, label_id: e.label_id, label };
        if let Some(other) = colours.insert(e.color, instance) {
            return Err(format!("instances {} and {id} share the colour {:?}", other.id, e.color));
        }
    }
    Ok(colours)
}
