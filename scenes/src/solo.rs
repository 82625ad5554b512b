//! Unity Perception's SOLO datasets (com.unity.perception 1.0, its SoloEndpoint), as its code
//! writes them (Unity-Technologies/com.unity.perception at 7e3d4c95, Runtime/GroundTruth/Consumers/
//! Solo):
//!
//! ```text
//! DIR/metadata.json, annotation_definitions.json,     written when the simulation ends (not read;
//!     metric_definitions.json, sensor_definitions.json  a folder without them is read, with a note)
//! DIR/sequence.<K>/step<M>.frame_data.json     per step: captures[], each a sensor's record
//!                                               (position, rotation x y z w, dimension [W, H],
//!                                               projection, matrix, filename) and its annotations[]
//! DIR/sequence.<K>/step<M>.<sensor>.png         the capture (RGBA; alpha dropped)
//! DIR/sequence.<K>/step<M>.<sensor>.<annotation id>.<ext>   each image annotation's file, named by
//!                                               its "filename": the instance segmentation PNG (8-bit
//!                                               RGBA), the depth EXR (R = metres), the normals EXR
//! ```
//!
//! Each capture with an InstanceSegmentationAnnotation is one scene, named `sequence.K/stepM`
//! (`sequence.K/stepM.<sensor id>` where a step has several such captures), in sequence then step
//! order, as numbers. Unity writes a step's frame_data.json after every file it names, so a step
//! is whole once that is there: one without it (its images written, a run stopped) is skipped
//! with a note; a frame_data.json naming a missing or empty file is refused in one line naming
//! the file. Every frame_data.json is parsed once, when the folder is opened (solo_step.rs); the
//! images' headers are checked when the scenes are listed.
//!
//! Instances: the colours of the annotation's `instances` (instanceId, labelId, labelName, color
//! RGBA), each the renderer id `instanceId`; (0, 0, 0, 255), the colour Unity gives instance index
//! 0 (nothing drawn, or an object without a Labeling), and (0, 0, 0, 0) are background; any other
//! colour stops the scene, naming the pixel. Categories: a categories.json beside the sequences
//! (its names are the labelNames), else id = labelId, name = labelName, and a labelId naming two
//! labels (or a label with two labelIds) is refused; labelId 0 (a label config starting at 0)
//! needs the categories.json. Depth: the DepthAnnotation's EXR, R (camera-space z in metres; 0
//! where nothing is drawn, background); `measurementStrategy` "Range" (distance to the camera) is
//! made planar through K. Normals: the NormalAnnotation's EXR, where there is one. Camera: K from
//! `matrix` and `dimension`, the pose from `position` and `rotation`; 3D boxes: each instance's
//! BoundingBox3DAnnotation value gives `pose` and `bbox_3d` (and its category the box's keypoints);
//! see solo_geometry.rs for the conventions. Each annotation carries `instance_id` (Unity's,
//! stable through the simulation) and `label_name`.

use crate::format::{SceneFormat, SceneIndex};
use crate::labels::{read_categories, CategoryGuide, RawScene};
use crate::solo_geometry::{decode_normal, planar_from_range};
use crate::solo_step::{parse_step, SoloScene, BACKGROUND, FRAME_DATA, INSTANCES};
use crate::{bad, file_error, SceneError};
use rayon::prelude::*;
use serde_json::{json, Map};
use std::collections::{BTreeMap, BTreeSet};
use std::io::BufReader;
use std::path::{Path, PathBuf};
use vkdiff_formats::image::{depth_exr_size, image_size, read_depth_exr, read_image, read_rgb_exr};
use vkdiff_render::camera::Camera;
use vkdiff_render::coco::Category;

/// `sequence.<K>` → K.
fn sequence_number(name: &str) -> Option<u64> {
    let k = name.strip_prefix("sequence.")?;
    (!k.is_empty() && k.bytes().all(|b| b.is_ascii_digit())).then(|| k.parse().ok())?
}

/// `step<M>.<rest>` → (M, rest).
fn step_of(name: &str) -> Option<(u64, &str)> {
    let (step, rest) = name.strip_prefix("step")?.split_once('.')?;
    (!step.is_empty() && step.bytes().all(|b| b.is_ascii_digit())).then(|| Some((step.parse().ok()?, rest)))?
}

/// A SOLO dataset's scenes, every frame_data.json parsed.
#[derive(Debug)]
pub struct SoloDataset {
    scenes: BTreeMap<PathBuf, SoloScene>,
    /// labelName → category.
    categories: BTreeMap<String, Category>,
    guides: BTreeMap<u32, CategoryGuide>,
    notes: Vec<String>,
}

/// A folder `sequence.<K>` holding a frame_data.json.
fn is_sequence(path: &Path) -> bool {
    let named = path.file_name().and_then(|n| n.to_str()).is_some_and(|n| sequence_number(n).is_some());
    named
        && std::fs::read_dir(path).is_ok_and(|entries| {
            entries.flatten().any(|e| {
                let name = e.file_name();
                step_of(&name.to_string_lossy()).is_some_and(|(_, rest)| rest == FRAME_DATA)
            })
        })
}

impl SoloDataset {
    /// The sequence folders among `paths` (a dataset's entries), in sequence order, or `dir`
    /// itself where it is one; None where there is none.
    pub fn find(dir: &Path, paths: &[PathBuf]) -> Option<Vec<PathBuf>> {
        if is_sequence(dir) {
            return Some(vec![dir.to_path_buf()]);
        }
        let mut found: Vec<(u64, PathBuf)> = paths
            .iter()
            .filter(|p| is_sequence(p))
            .filter_map(|p| Some((sequence_number(p.file_name()?.to_str()?)?, p.clone())))
            .collect();
        found.sort();
        (!found.is_empty()).then(|| found.into_iter().map(|(_, p)| p).collect())
    }

    /// Parses every step's frame_data.json under `sequences`, and categories.json in `dir`; the
    /// scenes' keys, in order. Steps without their frame_data.json are left out with a note.
    pub fn open(dir: &Path, sequences: &[PathBuf]) -> Result<(SoloDataset, Vec<PathBuf>), SceneError> {
        let mut notes = Vec::new();
        let root = sequences.first().is_some_and(|s| s.parent() == Some(dir));
        if root && !dir.join("metadata.json").is_file() {
            notes.push(
                "metadata.json is not there (Unity writes it and the definitions files when the simulation ends); \
                 the steps are read as they are"
                    .to_string(),
            );
        }
        let mut steps = Vec::new();
        for folder in sequences {
            let seq = folder.file_name().map_or(String::new(), |n| n.to_string_lossy().into_owned());
            let entries = std::fs::read_dir(folder).map_err(|e| SceneError::io(folder, e))?;
            let mut written: BTreeMap<u64, bool> = BTreeMap::new();
            for entry in entries.flatten() {
                let name = entry.file_name().to_string_lossy().into_owned();
                if let Some((step, rest)) = step_of(&name) {
                    *written.entry(step).or_default() |= rest == FRAME_DATA;
                }
            }
            for (step, whole) in written {
                if whole {
                    steps.push((folder.clone(), seq.clone(), step));
                } else {
                    notes.push(format!(
                        "{seq}/step{step} skipped: step{step}.{FRAME_DATA} is not written yet (Unity writes it after \
                         the step's other files)"
                    ));
                }
            }
        }
        let parsed: Vec<Result<Vec<(PathBuf, SoloScene)>, SceneError>> =
            steps.par_iter().map(|(folder, seq, step)| parse_step(folder, seq, *step)).collect();
        let mut scenes = BTreeMap::new();
        let mut keys = Vec::new();
        for step in parsed {
            for (key, scene) in step? {
                keys.push(key.clone());
                scenes.insert(key, scene);
            }
        }
        let ordered: Vec<&SoloScene> = keys.iter().map(|k| &scenes[k]).collect();
        let boxed: BTreeSet<&str> = ordered
            .iter()
            .flat_map(|s| s.colours.values().filter(|i| s.boxes.contains_key(&i.id)).map(|i| i.label.as_str()))
            .collect();
        let path = dir.join("categories.json");
        let (categories, guides) = if path.is_file() {
            let (listed, _, guides) = read_categories(&path)?;
            let named: BTreeMap<String, Category> = listed.into_iter().map(|c| (c.name.clone(), c)).collect();
            for scene in &ordered {
                if let Some(i) = scene.colours.values().find(|i| !named.contains_key(&i.label)) {
                    let why = format!(
                        "names no category `{}` (a labelName of {}); its names are the labelNames",
                        i.label, scene.name
                    );
                    return Err(SceneError::file(&path, why));
                }
            }
            (named, guides)
        } else {
            (categories_from_labels(&ordered)?, BTreeMap::new())
        };
        let categories = categories
            .into_iter()
            .map(|(name, c)| {
                let c =
                    if boxed.contains(name.as_str()) && c.keypoints.is_empty() { c.with_box_keypoints() } else { c };
                (name, c)
            })
            .collect();
        Ok((SoloDataset { scenes, categories, guides, notes }, keys))
    }

    fn scene(&self, key: &Path) -> Result<&SoloScene, SceneError> {
        self.scenes.get(key).ok_or_else(|| SceneError::new(format!("{} is not a listed SOLO step", key.display())))
    }
}

/// Categories from the labels as the steps give them: id = labelId, name = labelName.
fn categories_from_labels(scenes: &[&SoloScene]) -> Result<BTreeMap<String, Category>, SceneError> {
    let mut by_id: BTreeMap<i64, (&str, &str)> = BTreeMap::new();
    let mut by_name: BTreeMap<&str, (i64, &str)> = BTreeMap::new();
    for scene in scenes {
        for i in scene.colours.values() {
            let (id, label) = (i.label_id, i.label.as_str());
            if id <= 0 || id > u32::MAX as i64 {
                return Err(SceneError::new(format!(
                    "scene {}: labelId {id} (`{label}`): category ids start at 1 (a label config's Starting Label Id \
                     One); name the labels in a categories.json beside the sequences",
                    scene.name
                )));
            }
            match by_id.insert(id, (label, &scene.name)) {
                Some((other, first)) if other != label => {
                    return Err(SceneError::new(format!(
                    "labelId {id} is `{other}` in {first} and `{label}` in {}; name the labels in a categories.json \
                         beside the sequences",
                    scene.name
                )))
                }
                Some(kept) => {
                    by_id.insert(id, kept);
                }
                None => {}
            }
            match by_name.insert(label, (id, &scene.name)) {
                Some((other, first)) if other != id => {
                    return Err(SceneError::new(format!(
                        "label `{label}` is labelId {other} in {first} and {id} in {}; name the labels in a \
                         categories.json beside the sequences",
                        scene.name
                    )))
                }
                Some(kept) => {
                    by_name.insert(label, kept);
                }
                None => {}
            }
        }
    }
    Ok(by_name
        .into_iter()
        .map(|(name, (id, _))| (name.to_string(), Category::new(id as u32, name, "object")))
        .collect())
}

/// The instance image's header: 8-bit RGBA.
fn instance_header(folder: &Path, name: &str) -> Result<png::Reader<BufReader<std::fs::File>>, SceneError> {
    let file = std::fs::File::open(folder.join(name)).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => bad(name, "missing"),
        _ => bad(name, e),
    })?;
    let reader = png::Decoder::new(BufReader::new(file)).read_info().map_err(|e| bad(name, format!("bad PNG: {e}")))?;
    let info = reader.info();
    if (info.color_type, info.bit_depth) != (png::ColorType::Rgba, png::BitDepth::Eight) {
        let why = format!("{:?} {}-bit, not the 8-bit RGBA Unity writes", info.color_type, info.bit_depth as u8);
        return Err(bad(name, why));
    }
    Ok(reader)
}

/// Refuses `name` of `size` where the scene's depth is `depth`.
fn same_size(name: &str, size: (usize, usize), depth: (usize, usize)) -> Result<(), SceneError> {
    if size == depth {
        return Ok(());
    }
    Err(bad(name, format!("{}×{}, the depth is {}×{}", size.0, size.1, depth.0, depth.1)))
}

impl SoloScene {
    /// The depth's size; every other file's, and the capture's dimension, checked against it.
    fn check_sizes(&self, data_name: &str) -> Result<(usize, usize), SceneError> {
        let size = depth_exr_size(&self.folder.join(&self.depth)).map_err(file_error(&self.depth))?;
        let info = instance_header(&self.folder, &self.instances)?.info().size();
        same_size(&self.instances, (info.0 as usize, info.1 as usize), size)?;
        if let Some(rgb) = &self.rgb {
            same_size(rgb, image_size(&self.folder.join(rgb)).map_err(file_error(rgb))?, size)?;
        }
        if let Some(normals) = &self.normals {
            same_size(normals, depth_exr_size(&self.folder.join(normals)).map_err(file_error(normals))?, size)?;
        }
        let (w, h) = self.dimension;
        if (w as usize, h as usize) != size {
            let why = format!("the capture's dimension is [{w}, {h}], the depth {}×{}", size.0, size.1);
            return Err(bad(data_name, why));
        }
        Ok(size)
    }

    fn data_name(&self) -> String {
        let step = self.name.rsplit('/').next().unwrap_or_default();
        format!("{}.{FRAME_DATA}", step.split('.').next().unwrap_or_default())
    }
}

impl SceneFormat for SoloDataset {
    fn name(&self) -> &'static str {
        "unity perception solo"
    }

    fn scene_name(&self, key: &Path) -> String {
        self.scenes.get(key).map_or_else(|| key.display().to_string(), |s| s.name.clone())
    }

    fn index(&self, key: &Path) -> Result<SceneIndex, SceneError> {
        let scene = self.scene(key)?;
        let (width, height) = scene.check_sizes(&scene.data_name())?;
        let used: BTreeSet<&str> = scene.colours.values().map(|i| i.label.as_str()).collect();
        let mut categories: Vec<Category> = used.iter().map(|l| self.categories[*l].clone()).collect();
        categories.sort_by_key(|c| c.id);
        Ok(SceneIndex {
            width: width as u32,
            height: height as u32,
            prompt: None,
            categories,
            guides: self.guides.clone(),
        })
    }

    fn read(&self, key: &Path) -> Result<RawScene, SceneError> {
        let scene = self.scene(key)?;
        let data_name = scene.data_name();
        let (width, height) = scene.check_sizes(&data_name)?;
        let (mut depth, ..) = read_depth_exr(&scene.folder.join(&scene.depth)).map_err(file_error(&scene.depth))?;
        if scene.range {
            if let Some((k, _)) = &scene.camera {
                planar_from_range(&mut depth, width, *k);
            }
        }

        let mut reader = instance_header(&scene.folder, &scene.instances)?;
        let mut rgba = vec![0; reader.output_buffer_size().unwrap_or(0)];
        reader.next_frame(&mut rgba).map_err(|e| bad(&scene.instances, format!("bad PNG: {e}")))?;
        let mut labels = Vec::with_capacity(width * height);
        for (p, px) in rgba.chunks_exact(4).take(width * height).enumerate() {
            let colour = [px[0], px[1], px[2], px[3]];
            match scene.colours.get(&colour) {
                Some(instance) => labels.push(instance.id),
                None if BACKGROUND.contains(&colour) => labels.push(0),
                None => {
                    let why = format!(
                        "pixel ({}, {}) is {colour:?}, a colour the {INSTANCES} of {data_name} does not list",
                        p % width,
                        p / width
                    );
                    return Err(bad(&scene.instances, why));
                }
            }
        }

        let mut category_of = BTreeMap::new();
        let mut attributes = BTreeMap::new();
        for instance in scene.colours.values() {
            category_of.insert(instance.id, self.categories[&instance.label].id);
            let mut carried = Map::new();
            carried.insert("instance_id".into(), json!(instance.id));
            carried.insert("label_name".into(), json!(instance.label));
            if let Some((pose, bbox)) = scene.boxes.get(&instance.id) {
                carried.insert("pose".into(), pose.to_json());
                carried.insert("bbox_3d".into(), bbox.to_json());
            }
            attributes.insert(instance.id, carried);
        }
        let shaded = match &scene.rgb {
            Some(rgb) => Some(read_image(&scene.folder.join(rgb)).map_err(file_error(rgb))?.pixels),
            None => None,
        };
        let normals = match &scene.normals {
            Some(name) => {
                let (values, ..) = read_rgb_exr(&scene.folder.join(name)).map_err(file_error(name))?;
                Some(values.into_iter().map(decode_normal).collect())
            }
            None => None,
        };
        let (width, height) = (width as u32, height as u32);
        let camera = scene.camera.clone().map(|(k, pose)| Camera::from_intrinsics(width, height, k, pose));
        Ok(RawScene {
            width,
            height,
            depth,
            labels,
            category_of,
            attributes,
            shaded,
            normals,
            camera,
            ..RawScene::default()
        })
    }

    fn notes(&self) -> Vec<String> {
        self.notes.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sequences_and_steps_are_numbers() {
        assert_eq!(sequence_number("sequence.10"), Some(10));
        assert_eq!(sequence_number("sequence."), None);
        assert_eq!(sequence_number("sequence.1a"), None);
        assert_eq!(step_of("step12.frame_data.json"), Some((12, "frame_data.json")));
        assert_eq!(step_of("step3.camera.instance segmentation.png"), Some((3, "camera.instance segmentation.png")));
        assert_eq!(step_of("step.camera.png"), None);
        assert_eq!(step_of("steps3.png"), None);
    }
}
