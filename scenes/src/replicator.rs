//! NVIDIA Omniverse Replicator's BasicWriter output (Isaac Sim's too): one folder of frames, each
//! frame N (zero-padded, four digits by default) written as
//!
//! ```text
//! rgb_N.png                                 the render, RGBA (alpha dropped)
//! distance_to_image_plane_N.npy             float32 H×W, planar depth in scene units (metres in
//!                                           Isaac Sim); inf where nothing is hit
//! instance_segmentation_N.png               8-bit RGBA, one colour per instance
//!                                           (colorize_instance_segmentation=True, the default)
//! instance_segmentation_mapping_N.json      "(R, G, B, A)" → prim path
//! instance_segmentation_semantics_mapping_N.json   "(R, G, B, A)" → {"class": …}
//! camera_params_N.json                      optional: cameraProjection, cameraViewTransform,
//!                                           renderProductResolution, cameraModel, …
//! bounding_box_3d_N.npy                     optional (every frame or none): each labelled prim's
//!                                           extent and local-to-world transform
//! bounding_box_3d_labels_N.json             semanticId → {"class": …}
//! bounding_box_3d_prim_paths_N.json         each row's prim path
//! ```
//!
//! Each frame is one scene, named N, in frame order. BasicWriter writes asynchronously: a frame is
//! whole once its semantics mapping (and, with 3D boxes, its box files) is written, so a last
//! frame without them is skipped (with a note) and an earlier one is refused. The reserved
//! BACKGROUND and UNLABELLED entries are background; every other colour is an instance of its
//! class, its annotation carrying the prim path, and its box row's `bbox_3d` and `pose` (matched
//! by prim path). Category ids: a categories.json beside the frames (its names the classes), else
//! the classes of all frames sorted by name, id = 1 + the index; with 3D boxes, each category's
//! keypoints are the box's. Every JSON file and box row is parsed once, when the folder is opened;
//! the images' and the depth's headers are checked when the scenes are listed.

use crate::format::{SceneFormat, SceneIndex};
use crate::labels::{read_categories, CategoryGuide, RawScene};
use crate::replicator_boxes::{box_files, frame_boxes, FrameBoxes, BOXES};
use crate::replicator_camera::{intrinsics_of, view_of, CameraParams};
use crate::replicator_files::{depth_header, instance_header, read_json, refuse, same_size};
use crate::SceneError;
use crate::{bad, file_error};
use rayon::prelude::*;
use serde_json::{json, Map};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use vkdiff_formats::image::{image_size, read_image};
use vkdiff_render::camera::{Camera, Pose};
use vkdiff_render::coco::Category;

/// The classes BasicWriter reserves: pixels of no prim, and of prims without semantics.
const RESERVED: [&str; 2] = ["BACKGROUND", "UNLABELLED"];

/// The files of frame N, by what they hold.
const RGB: &str = "rgb_";
const DEPTH: &str = "distance_to_image_plane_";
const INSTANCES: &str = "instance_segmentation_";
const PRIMS: &str = "instance_segmentation_mapping_";
const SEMANTICS: &str = "instance_segmentation_semantics_mapping_";
const CAMERA: &str = "camera_params_";

pub(crate) fn file(prefix: &str, frame: &str, ext: &str) -> String {
    format!("{prefix}{frame}.{ext}")
}

/// A frame's number as BasicWriter spells it (`0042`, or `3_0042` after an on_time trigger), to
/// order frames as numbers; None for another name.
fn frame_key(frame: &str) -> Option<Vec<u64>> {
    frame
        .split('_')
        .map(|p| (!p.is_empty() && p.bytes().all(|b| b.is_ascii_digit())).then(|| p.parse().ok())?)
        .collect()
}

/// The frame of a file `<prefix><N>.<ext>`.
fn frame_of<'a>(name: &'a str, prefix: &str, ext: &str) -> Option<&'a str> {
    let frame = name.strip_prefix(prefix)?.strip_suffix(ext)?.strip_suffix('.')?;
    frame_key(frame).is_some().then_some(frame)
}

/// One colour of a frame's instance image: its prim and class.
#[derive(Debug)]
struct Colour {
    prim: Option<String>,
    class: String,
}

/// One whole frame, its JSON files parsed.
#[derive(Debug)]
struct ReplicatorFrame {
    frame: String,
    colours: BTreeMap<[u8; 4], Colour>,
    /// The colours the mappings give BACKGROUND or UNLABELLED: background.
    reserved: BTreeSet<[u8; 4]>,
    /// fx, fy, cx, cy and the pose, from camera_params; None where it is missing or not a pinhole.
    camera: Option<([f64; 4], Pose)>,
    /// renderProductResolution, checked against the images.
    resolution: Option<[u32; 2]>,
    metres_per_unit: f64,
    /// The 3D boxes, by prim path.
    boxes: FrameBoxes,
}

/// A folder of BasicWriter frames.
#[derive(Debug)]
pub struct ReplicatorFrames {
    /// By the frame's rgb file.
    frames: BTreeMap<PathBuf, ReplicatorFrame>,
    /// Class → category.
    categories: BTreeMap<String, Category>,
    guides: BTreeMap<u32, CategoryGuide>,
    notes: Vec<String>,
}

impl ReplicatorFrames {
    /// The frames among `paths` (a folder's entries), by their numbers as written (`0042`), in
    /// frame order: None where no file is named as BasicWriter names an instance segmentation
    /// mapping.
    pub fn find(paths: &[PathBuf]) -> Option<Vec<String>> {
        let names: Vec<String> =
            paths.iter().filter_map(|p| p.file_name()).map(|n| n.to_string_lossy().into_owned()).collect();
        let mapped = names.iter().any(|n| frame_of(n, PRIMS, "json").or(frame_of(n, SEMANTICS, "json")).is_some());
        if !mapped {
            return None;
        }
        // Every frame any of its files names, so that a frame missing one is found and refused.
        let mut frames: Vec<String> = names
            .iter()
            .filter_map(|n| {
                [(RGB, "png"), (RGB, "jpg"), (RGB, "jpeg"), (DEPTH, "npy"), (INSTANCES, "png"), (SEMANTICS, "json")]
                    .iter()
                    .find_map(|(prefix, ext)| frame_of(n, prefix, ext))
                    .or_else(|| frame_of(n, PRIMS, "json"))
            })
            .map(str::to_string)
            .collect::<BTreeSet<_>>()
            .into_iter()
            .collect();
        frames.sort_by_key(|f| frame_key(f));
        Some(frames)
    }

    /// Parses the frames' JSON files, their 3D boxes and categories.json in `dir`; the whole
    /// frames' rgb files, in frame order. A last frame without its semantics mapping (or, where
    /// the frames have 3D boxes, without its box files) is left out with a note.
    pub fn open(dir: &Path, frames: &[String]) -> Result<(ReplicatorFrames, Vec<PathBuf>), SceneError> {
        let mut whole = frames.to_vec();
        let mut notes = Vec::new();
        let complete = |f: &str| dir.join(file(SEMANTICS, f, "json")).is_file();
        // bounding_box_3d=True writes the box files of every frame, or of none.
        let boxed = frames.iter().any(|f| dir.join(file(BOXES, f, "npy")).is_file());
        let missing_box = |f: &str| box_files(f).into_iter().find(|name| boxed && !dir.join(name).is_file());
        if let Some(last) = whole.last().filter(|f| !complete(f)).cloned() {
            whole.pop();
            notes.push(format!(
                "frame {last} skipped: {} is not written yet (BasicWriter writes a frame's files in turn, that one last)",
                file(SEMANTICS, &last, "json")
            ));
        } else if let Some(name) = whole.last().and_then(|f| missing_box(f)) {
            notes.push(format!("frame {} skipped: {name} is not written yet", whole.pop().unwrap_or_default()));
        }
        if let Some(broken) = whole.iter().find(|f| !complete(f)) {
            let why = "missing; BasicWriter writes it last, and only the last frame may be cut short";
            return Err(refuse(broken, &file(SEMANTICS, broken, "json"), why));
        }
        if let Some((broken, name)) = whole.iter().find_map(|f| Some((f, missing_box(f)?))) {
            let why = "missing; the other frames have 3D boxes, which bounding_box_3d=True writes for every frame";
            return Err(refuse(broken, &name, why));
        }
        let parsed: Vec<Result<(PathBuf, ReplicatorFrame), SceneError>> =
            whole.par_iter().map(|f| parse_frame(dir, f, boxed)).collect();
        let mut by_rgb = BTreeMap::new();
        let mut keys = Vec::new();
        for frame in parsed {
            let (rgb, frame) = frame?;
            keys.push(rgb.clone());
            by_rgb.insert(rgb, frame);
        }
        let classes: BTreeSet<&str> =
            by_rgb.values().flat_map(|f| f.colours.values()).map(|c| c.class.as_str()).collect();
        let path = dir.join("categories.json");
        let (mut categories, guides) = if path.is_file() {
            let (listed, _, guides) = read_categories(&path)?;
            let mut named = BTreeMap::new();
            for category in listed {
                named.insert(category.name.clone(), category);
            }
            if let Some(class) = classes.iter().find(|c| !named.contains_key(**c)) {
                let frame = by_rgb.values().find(|f| f.colours.values().any(|c| c.class == *class));
                let frame = frame.map_or(String::new(), |f| f.frame.clone());
                return Err(SceneError::file(
                    &path,
                    format!("names no category `{class}` (a class of frame {frame}); its names are the classes"),
                ));
            }
            (named, guides)
        } else {
            // Sorted names: ids that do not depend on which frames are read, or in which order.
            let named = classes.iter().enumerate().map(|(k, &name)| {
                let category = Category::new(k as u32 + 1, name, "object");
                (name.to_string(), category)
            });
            (named.collect(), BTreeMap::new())
        };
        if boxed {
            // Each box's corners are its instance's keypoints, unless categories.json names others.
            for category in categories.values_mut().filter(|c| c.keypoints.is_empty()) {
                *category = std::mem::take(category).with_box_keypoints();
            }
        }
        Ok((ReplicatorFrames { frames: by_rgb, categories, guides, notes }, keys))
    }

    fn frame(&self, rgb: &Path) -> Result<&ReplicatorFrame, SceneError> {
        self.frames.get(rgb).ok_or_else(|| SceneError::new(format!("{} is not a listed frame", rgb.display())))
    }
}

/// Frame `frame`'s rgb file (PNG, else JPEG) and its parsed JSON files, its 3D boxes too where
/// the frames are `boxed`.
fn parse_frame(dir: &Path, frame: &str, boxed: bool) -> Result<(PathBuf, ReplicatorFrame), SceneError> {
    let rgb = ["png", "jpg", "jpeg"].iter().map(|e| dir.join(file(RGB, frame, e))).find(|p| p.is_file());
    let rgb = rgb.ok_or_else(|| refuse(frame, &file(RGB, frame, "png"), "missing (the frame's render)"))?;
    let prims: BTreeMap<String, String> = read_json(dir, frame, &file(PRIMS, frame, "json"))?;
    let semantics: BTreeMap<String, BTreeMap<String, serde_json::Value>> =
        read_json(dir, frame, &file(SEMANTICS, frame, "json"))?;
    let mut colours = BTreeMap::new();
    let mut reserved = BTreeSet::new();
    for (key, labels) in &semantics {
        let name = file(SEMANTICS, frame, "json");
        let colour = parse_colour(key).ok_or_else(|| {
            let why = format!("key `{key}` is not a colour \"(R, G, B, A)\" (only colourised instance maps are read)");
            refuse(frame, &name, why)
        })?;
        let class = labels.get("class").and_then(|c| c.as_str()).ok_or_else(|| {
            refuse(frame, &name, format!("{key} has no \"class\" (semantic_types other than class are not read)"))
        })?;
        let prim = prims.get(key).cloned();
        if RESERVED.contains(&class) || prim.as_deref().is_some_and(|p| RESERVED.contains(&p)) {
            reserved.insert(colour);
            continue;
        }
        colours.insert(colour, Colour { prim, class: class.to_string() });
    }
    let name = file(PRIMS, frame, "json");
    for (key, prim) in &prims {
        if parse_colour(key).is_none() {
            return Err(refuse(frame, &name, format!("key `{key}` is not a colour \"(R, G, B, A)\"")));
        }
        if RESERVED.contains(&prim.as_str()) {
            reserved.extend(parse_colour(key));
        } else if !semantics.contains_key(key) {
            let why = format!("{key} ({prim}) has no class in {}", file(SEMANTICS, frame, "json"));
            return Err(refuse(frame, &name, why));
        }
    }
    let camera_file = file(CAMERA, frame, "json");
    let params: Option<CameraParams> =
        dir.join(&camera_file).is_file().then(|| read_json(dir, frame, &camera_file)).transpose()?;
    let metres_per_unit = params.as_ref().and_then(|p| p.meters_per_scene_unit).unwrap_or(1.0);
    if !(metres_per_unit.is_finite() && metres_per_unit > 0.0) {
        return Err(refuse(frame, &camera_file, format!("metersPerSceneUnit {metres_per_unit} is not positive")));
    }
    let (intrinsics, view) = match &params {
        Some(p) => (intrinsics_of(p), view_of(p)),
        None => (Ok(None), Ok(None)),
    };
    let intrinsics = intrinsics.map_err(|why| refuse(frame, &camera_file, &why))?;
    let view = view.map_err(|why| refuse(frame, &camera_file, &why))?;
    let pose = view.as_ref().map_or(Pose::Unknown, |v| v.world_from_camera(metres_per_unit));
    let camera = intrinsics.map(|k| (k, pose));
    let boxes = match boxed {
        true => {
            let class_of = colours.values().filter_map(|c| Some((c.prim.as_deref()?, c.class.as_str()))).collect();
            frame_boxes(dir, frame, &class_of, view.as_ref(), metres_per_unit)?
        }
        false => FrameBoxes::new(),
    };
    let resolution = params.map(|p| p.render_product_resolution);
    let frame = frame.to_string();
    Ok((rgb, ReplicatorFrame { frame, colours, reserved, camera, resolution, metres_per_unit, boxes }))
}

/// "(R, G, B, A)" as BasicWriter's colourised mappings key a colour.
fn parse_colour(key: &str) -> Option<[u8; 4]> {
    let inner = key.trim().strip_prefix('(')?.strip_suffix(')')?;
    let values: Vec<u8> = inner.split(',').map(|v| v.trim().parse().ok()).collect::<Option<_>>()?;
    values.try_into().ok()
}

impl SceneFormat for ReplicatorFrames {
    fn name(&self) -> &'static str {
        "replicator basicwriter"
    }

    fn scene_name(&self, rgb: &Path) -> String {
        self.frames.get(rgb).map_or_else(|| rgb.display().to_string(), |f| f.frame.clone())
    }

    fn index(&self, rgb: &Path) -> Result<SceneIndex, SceneError> {
        let frame = self.frame(rgb)?;
        let dir = rgb.parent().unwrap_or(Path::new("."));
        let depth_name = file(DEPTH, &frame.frame, "npy");
        let (_, width, height, _) = depth_header(dir, &depth_name)?;
        let rgb_name = crate::name_of(rgb);
        same_size(&rgb_name, image_size(rgb).map_err(file_error(&rgb_name))?, (width, height))?;
        let instance_name = file(INSTANCES, &frame.frame, "png");
        let info = instance_header(dir, &instance_name)?.info().size();
        same_size(&instance_name, (info.0 as usize, info.1 as usize), (width, height))?;
        if let Some([w, h]) = frame.resolution {
            same_size(&file(CAMERA, &frame.frame, "json"), (w as usize, h as usize), (width, height))?;
        }
        let used: BTreeSet<&str> = frame.colours.values().map(|c| c.class.as_str()).collect();
        let mut categories: Vec<Category> = used.iter().map(|c| self.categories[*c].clone()).collect();
        categories.sort_by_key(|c| c.id);
        Ok(SceneIndex {
            width: width as u32,
            height: height as u32,
            prompt: None,
            categories,
            guides: self.guides.clone(),
        })
    }

    fn read(&self, rgb: &Path) -> Result<RawScene, SceneError> {
        let frame = self.frame(rgb)?;
        let dir = rgb.parent().unwrap_or(Path::new("."));
        let depth_name = file(DEPTH, &frame.frame, "npy");
        let (npy, width, height, double) = depth_header(dir, &depth_name)?;
        let fortran = npy.order() == npyz::Order::Fortran;
        let read = |e: std::io::Error| bad(&depth_name, format!("unreadable: {e}"));
        let values: Vec<f32> = if double {
            npy.into_vec::<f64>().map_err(read)?.into_iter().map(|v| v as f32).collect()
        } else {
            npy.into_vec::<f32>().map_err(read)?
        };
        let scale = frame.metres_per_unit as f32;
        let at = |p: usize| if fortran { values[(p % width) * height + p / width] } else { values[p] };
        let depth = (0..width * height).map(|p| at(p) * scale).collect();

        let instance_name = file(INSTANCES, &frame.frame, "png");
        let mut reader = instance_header(dir, &instance_name)?;
        let size = reader.info().size();
        same_size(&instance_name, (size.0 as usize, size.1 as usize), (width, height))?;
        let mut rgba = vec![0; reader.output_buffer_size().unwrap_or(0)];
        reader.next_frame(&mut rgba).map_err(|e| bad(&instance_name, format!("bad PNG: {e}")))?;
        // Renderer ids in colour order; the reserved colours, and every colour the mapping lists as
        // BACKGROUND or UNLABELLED, are 0.
        let ids: BTreeMap<[u8; 4], u32> = frame.colours.keys().enumerate().map(|(k, &c)| (c, k as u32 + 1)).collect();
        let mut labels = Vec::with_capacity(width * height);
        for (p, px) in rgba.chunks_exact(4).take(width * height).enumerate() {
            let colour = [px[0], px[1], px[2], px[3]];
            match ids.get(&colour) {
                Some(&id) => labels.push(id),
                None if frame.reserved.contains(&colour) => labels.push(0),
                None => {
                    let why = format!(
                        "pixel ({}, {}) is {colour:?}, a colour {} does not list",
                        p % width,
                        p / width,
                        file(PRIMS, &frame.frame, "json")
                    );
                    return Err(bad(&instance_name, why));
                }
            }
        }
        let mut category_of = BTreeMap::new();
        let mut attributes = BTreeMap::new();
        for (colour, entry) in &frame.colours {
            let id = ids[colour];
            category_of.insert(id, self.categories[&entry.class].id);
            let mut carried = Map::new();
            if let Some(prim) = &entry.prim {
                carried.insert("prim_path".into(), json!(prim));
                if let Some((bbox, pose)) = frame.boxes.get(prim) {
                    carried.insert("bbox_3d".into(), bbox.to_json());
                    carried.extend(pose.map(|p| ("pose".to_string(), p.to_json())));
                }
            }
            carried.insert("class".into(), json!(entry.class));
            attributes.insert(id, carried);
        }
        let rgb_name = crate::name_of(rgb);
        let shaded = read_image(rgb).map_err(file_error(&rgb_name))?;
        same_size(&rgb_name, (shaded.width, shaded.height), (width, height))?;
        let (width, height) = (width as u32, height as u32);
        let camera = frame.camera.clone().map(|(k, pose)| Camera::from_intrinsics(width, height, k, pose));
        Ok(RawScene {
            width,
            height,
            depth,
            labels,
            category_of,
            attributes,
            shaded: Some(shaded.pixels),
            normals: None,
            camera,
            ..RawScene::default()
        })
    }

    fn notes(&self) -> Vec<String> {
        self.notes.clone()
    }
}
