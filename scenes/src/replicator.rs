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
//! ```
//!
//! Each frame is one scene, named N, in frame order. BasicWriter writes asynchronously: a frame is
//! whole once its semantics mapping is written, so a last frame without it is skipped (with a
//! note) and an earlier one is refused. The reserved BACKGROUND and UNLABELLED entries are
//! background; every other colour is an instance of its class, its annotation carrying the prim
//! path. Category ids: a categories.json beside the frames (its names the classes), else the
//! classes of all frames sorted by name, id = 1 + the index. Every JSON file is parsed once, when
//! the folder is opened; the images' and the depth's headers are checked when the scenes are
//! listed.

use crate::format::{SceneFormat, SceneIndex};
use crate::labels::{read_categories, CategoryGuide, RawScene};
use crate::SceneError;
use rayon::prelude::*;
use serde::Deserialize;
use serde_json::{json, Map};
use std::collections::{BTreeMap, BTreeSet};
use std::io::BufReader;
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

fn file(prefix: &str, frame: &str, ext: &str) -> String {
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

/// camera_params_N.json, the fields read (the lens fields are left alone).
#[derive(Deserialize)]
#[serde(rename_all = "camelCase")]
struct CameraParams {
    camera_projection: Vec<f64>,
    camera_view_transform: Option<Vec<f64>>,
    render_product_resolution: [u32; 2],
    camera_model: Option<String>,
    meters_per_scene_unit: Option<f64>,
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

/// `why`, about `file` (of the frame being read, which the refusal names).
fn bad(file: &str, why: impl std::fmt::Display) -> SceneError {
    SceneError::new(format!("{file}: {why}"))
}

/// `why`, about `file` of frame `frame`, before the frames are listed.
fn refuse(frame: &str, file: &str, why: impl std::fmt::Display) -> SceneError {
    SceneError::new(format!("frame {frame}: {file}: {why}"))
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

    /// Parses the frames' JSON files and categories.json in `dir`; the whole frames' rgb files, in
    /// frame order. A last frame without its semantics mapping is left out with a note.
    pub fn open(dir: &Path, frames: &[String]) -> Result<(ReplicatorFrames, Vec<PathBuf>), SceneError> {
        let mut whole = frames.to_vec();
        let mut notes = Vec::new();
        let complete = |f: &str| dir.join(file(SEMANTICS, f, "json")).is_file();
        if let Some(last) = whole.last().filter(|f| !complete(f)).cloned() {
            whole.pop();
            notes.push(format!(
                "frame {last} skipped: {} is not written yet (BasicWriter writes a frame's files in turn, that one last)",
                file(SEMANTICS, &last, "json")
            ));
        }
        if let Some(broken) = whole.iter().find(|f| !complete(f)) {
            let why = "missing; BasicWriter writes it last, and only the last frame may be cut short";
            return Err(refuse(broken, &file(SEMANTICS, broken, "json"), why));
        }
        let parsed: Vec<Result<(PathBuf, ReplicatorFrame), SceneError>> =
            whole.par_iter().map(|f| parse_frame(dir, f)).collect();
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
        let (categories, guides) = if path.is_file() {
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
        Ok((ReplicatorFrames { frames: by_rgb, categories, guides, notes }, keys))
    }

    fn frame(&self, rgb: &Path) -> Result<&ReplicatorFrame, SceneError> {
        self.frames.get(rgb).ok_or_else(|| SceneError::new(format!("{} is not a listed frame", rgb.display())))
    }
}

/// Frame `frame`'s rgb file (PNG, else JPEG) and its parsed JSON files.
fn parse_frame(dir: &Path, frame: &str) -> Result<(PathBuf, ReplicatorFrame), SceneError> {
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
    let camera = match &params {
        Some(p) => camera_of(p, metres_per_unit).map_err(|why| refuse(frame, &camera_file, why))?,
        None => None,
    };
    let resolution = params.map(|p| p.render_product_resolution);
    let frame = frame.to_string();
    Ok((rgb, ReplicatorFrame { frame, colours, reserved, camera, resolution, metres_per_unit }))
}

fn read_json<T: serde::de::DeserializeOwned>(dir: &Path, frame: &str, name: &str) -> Result<T, SceneError> {
    let text = std::fs::read_to_string(dir.join(name)).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => refuse(frame, name, "missing"),
        _ => refuse(frame, name, e),
    })?;
    serde_json::from_str(&text).map_err(|e| refuse(frame, name, format!("not BasicWriter's format: {e}")))
}

/// "(R, G, B, A)" as BasicWriter's colourised mappings key a colour.
fn parse_colour(key: &str) -> Option<[u8; 4]> {
    let inner = key.trim().strip_prefix('(')?.strip_suffix(')')?;
    let values: Vec<u8> = inner.split(',').map(|v| v.trim().parse().ok()).collect::<Option<_>>()?;
    values.try_into().ok()
}

/// K and the pose from camera_params: None where the camera is not a pinhole (a fisheye model, an
/// orthographic or skewed projection); a view transform that is not a rotation and a translation
/// is refused.
fn camera_of(p: &CameraParams, metres_per_unit: f64) -> Result<Option<([f64; 4], Pose)>, String> {
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
    if !pinhole {
        return Ok(None);
    }
    // Row-vector convention (the transpose of OpenGL's matrix): a point in the camera's USD axes
    // (x right, y up, looking along −z) goes to clip space as [x y z 1]·P, then NDC [−1, 1] spans
    // the image's pixel edges, y up. In OpenCV's axes and pixel centres:
    let (w, h) = (w as f64, h as f64);
    let intrinsics = [p00 * w / 2.0, p11 * h / 2.0, w / 2.0 * (1.0 - p20) - 0.5, h / 2.0 * (1.0 + p21) - 0.5];
    let Some(view) = &p.camera_view_transform else {
        return Ok(Some((intrinsics, Pose::Unknown)));
    };
    let &[v00, v01, v02, v03, v10, v11, v12, v13, v20, v21, v22, v23, v30, v31, v32, v33] = &view[..] else {
        return Err(format!("cameraViewTransform has {} values, not 16 (4×4)", view.len()));
    };
    if [v03, v13, v23, v33] != [0.0, 0.0, 0.0, 1.0] {
        return Err("cameraViewTransform's last column is not [0, 0, 0, 1] (row-vector convention)".into());
    }
    // camera = world · V: the rotation world → camera is Vᵀ's 3×3, its translation V's last row.
    let r = [[v00, v10, v20], [v01, v11, v21], [v02, v12, v22]];
    let t = [v30, v31, v32];
    for i in 0..3 {
        for j in 0..3 {
            let dot: f64 = (0..3).map(|k| r[i][k] * r[j][k]).sum();
            if (dot - if i == j { 1.0 } else { 0.0 }).abs() > 1e-4 {
                return Err("cameraViewTransform is not a rotation and a translation".into());
            }
        }
    }
    // World from camera: [Rᵀ | −Rᵀt], scene units to metres; USD's camera axes to OpenCV's (y and z
    // turned: columns 1 and 2 negated).
    let centre = |j: usize| -(0..3).map(|k| r[k][j] * t[k]).sum::<f64>() * metres_per_unit;
    let row = |j: usize| [r[0][j], -r[1][j], -r[2][j], centre(j)];
    Ok(Some((intrinsics, Pose::Given([row(0), row(1), row(2), [0.0, 0.0, 0.0, 1.0]]))))
}

/// A file's error, naming it.
fn file_error(name: &str) -> impl Fn(vkdiff_formats::Error) -> SceneError + '_ {
    move |e| match e {
        vkdiff_formats::Error::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound => {
            bad(name, "missing")
        }
        vkdiff_formats::Error::Io { source, .. } => bad(name, source),
        vkdiff_formats::Error::Format { why, .. } => bad(name, why),
        vkdiff_formats::Error::Tensor(why) => bad(name, why),
    }
}

fn open_file(dir: &Path, name: &str) -> Result<BufReader<std::fs::File>, SceneError> {
    let f = std::fs::File::open(dir.join(name)).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => bad(name, "missing"),
        _ => bad(name, e),
    })?;
    Ok(BufReader::new(f))
}

/// A .npy file, its header read.
type Npy = npyz::NpyFile<BufReader<std::fs::File>>;

/// The depth file's header: a 2-D float array; its width, height, and whether it is float64.
fn depth_header(dir: &Path, name: &str) -> Result<(Npy, usize, usize, bool), SceneError> {
    let npy = npyz::NpyFile::new(open_file(dir, name)?).map_err(|e| bad(name, format!("not a .npy file: {e}")))?;
    let &[rows, cols] = npy.shape() else {
        return Err(bad(name, format!("shape {:?}; distance_to_image_plane is H×W", npy.shape())));
    };
    match npy.dtype() {
        npyz::DType::Plain(t) if t.type_char() == npyz::TypeChar::Float && matches!(t.size_field(), 4 | 8) => {
            let double = t.size_field() == 8;
            Ok((npy, cols as usize, rows as usize, double))
        }
        npyz::DType::Plain(t) => Err(bad(name, format!("dtype {t}; distance_to_image_plane is float32"))),
        _ => Err(bad(name, "a structured array; distance_to_image_plane is float32")),
    }
}

/// The instance image's header: 8-bit RGBA, (width, height).
fn instance_header(dir: &Path, name: &str) -> Result<png::Reader<BufReader<std::fs::File>>, SceneError> {
    let reader =
        png::Decoder::new(open_file(dir, name)?).read_info().map_err(|e| bad(name, format!("bad PNG: {e}")))?;
    let info = reader.info();
    if (info.color_type, info.bit_depth) != (png::ColorType::Rgba, png::BitDepth::Eight) {
        let why = format!(
            "{:?} {:?}-bit, not 8-bit RGBA; only colorize_instance_segmentation=True (BasicWriter's default) is read",
            info.color_type, info.bit_depth as u8
        );
        return Err(bad(name, why));
    }
    Ok(reader)
}

/// Refuses `name` of `size` where the frame's depth is `depth`.
fn same_size(name: &str, size: (usize, usize), depth: (usize, usize)) -> Result<(), SceneError> {
    if size == depth {
        return Ok(());
    }
    Err(bad(name, format!("{}×{}, the frame's depth is {}×{}", size.0, size.1, depth.0, depth.1)))
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
