//! BOP scenes, as BOP's datasets and BlenderProc's `write_bop` store them: a split folder of scene
//! folders (`000000/`, `000001/`, …), or one scene folder, each holding
//!
//! ```text
//! scene_camera.json            per image id: cam_K (3×3, row-major), depth_scale (a depth step in
//!                              mm), and where given cam_R_w2c (3×3) and cam_t_w2c (mm), OpenCV axes
//! scene_gt.json                per image id: a list of {obj_id, cam_R_m2c, cam_t_m2c (mm)}, gt id
//!                              = the index in that list
//! depth/{im:06d}.png           16-bit grey, planar depth (camera-space z) in steps of depth_scale
//!                              mm; 0 = no depth
//! mask_visib/{im:06d}_{gt:06d}.png   8-bit grey, the gt's visible pixels non-zero (255)
//! mask/{im:06d}_{gt:06d}.png   optional: the gt's whole silhouette, hidden parts too (amodal)
//! rgb/{im:06d}.png or .jpg     the render (PBR renders: PNG; photos: JPEG), or gray/ (grey)
//! ```
//!
//! Each image is one scene, named `<scene>/<im>` (`000001/000042`), in scene then image order.
//! Every image listed in scene_camera.json is one: scene_gt.json must list it, and its depth,
//! render and a visible mask for each of its gts must be there (checked from their headers when
//! the scenes are listed; both JSON files are parsed once). The instances are the gts (renderer id
//! gt + 1), each of category obj_id, their annotations carrying `obj_id`, `gt_id` and `pose`
//! (cam_R_m2c and cam_t_m2c, in metres), their amodal masks where the scene has mask/, and, where
//! the dataset's models/models_info.json gives the object's box, `bbox_3d` (and so the box's
//! keypoints). Category names: a categories.json beside the scene folders, else
//! `obj_<id, six digits>` (the name of the object's model file, models/obj_000001.ply).
//! scene_gt_info.json is not read.

use crate::bop_geometry::{models_info_path, read_models_info, world_from_camera};
use crate::format::{SceneFormat, SceneIndex};
use crate::labels::{read_categories, CategoryGuide, RawScene};
use crate::{bad, SceneError};
use rayon::prelude::*;
use serde::Deserialize;
use serde_json::{json, Map};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use vkdiff_formats::image::{grey_png_size, image_size, read_grey_png, read_image};
use vkdiff_render::camera::{Camera, Pose};
use vkdiff_render::coco::Category;
use vkdiff_render::geometry::{AmodalMask, Box3, ObjectPose};

/// What a folder must hold to be a BOP scene.
const SCENE_FILES: [&str; 2] = ["scene_camera.json", "scene_gt.json"];

/// One image's entry in scene_camera.json (other fields, such as T-LESS's `elev` and `mode`, are
/// left alone).
#[derive(Deserialize)]
struct CameraEntry {
    #[serde(rename = "cam_K")]
    k: Vec<f64>,
    depth_scale: Option<f64>,
    #[serde(rename = "cam_R_w2c")]
    r_w2c: Option<Vec<f64>>,
    #[serde(rename = "cam_t_w2c")]
    t_w2c: Option<Vec<f64>>,
}

/// One gt of scene_gt.json.
#[derive(Clone, Deserialize)]
struct GtEntry {
    obj_id: u32,
    #[serde(rename = "cam_R_m2c")]
    r: Vec<f64>,
    #[serde(rename = "cam_t_m2c")]
    t: Vec<f64>,
}

/// One image of a scene, its JSON entries checked.
#[derive(Debug)]
struct BopImage {
    scene: PathBuf,
    im_id: u64,
    /// fx, fy, cx, cy.
    intrinsics: [f64; 4],
    depth_scale: f64,
    pose: Pose,
    gts: Vec<Gt>,
}

#[derive(Debug)]
struct Gt {
    obj_id: u32,
    /// cam_R_m2c and cam_t_m2c, the translation in metres.
    pose: ObjectPose,
}

/// BOP scenes, every image's entries parsed from its scene's JSON files once.
#[derive(Debug)]
pub struct BopScenes {
    /// By the image's key: its scene folder joined with its six-digit id.
    images: BTreeMap<PathBuf, BopImage>,
    /// categories.json beside the scene folders, naming the obj_ids; else `obj_<id>`.
    names: Option<Vec<Category>>,
    guides: BTreeMap<u32, CategoryGuide>,
    /// Each obj_id's 3D box, from the dataset's models_info.json where it has one.
    models: BTreeMap<u32, Box3>,
}

/// Whether `dir` is a BOP scene folder.
pub fn is_bop_scene(dir: &Path) -> bool {
    SCENE_FILES.iter().all(|f| dir.join(f).is_file())
}

fn is_hidden(path: &Path) -> bool {
    path.file_name().is_some_and(|n| n.to_string_lossy().starts_with('.'))
}

impl BopScenes {
    /// The scene folders of `dir` (whose entries are `paths`): `dir` itself where it is one, else
    /// its folders (hidden ones skipped) where one of them is; None where there is none.
    pub fn find(dir: &Path, paths: &[PathBuf]) -> Option<Vec<PathBuf>> {
        if is_bop_scene(dir) {
            return Some(vec![dir.to_path_buf()]);
        }
        let folders: Vec<PathBuf> = paths.iter().filter(|p| p.is_dir() && !is_hidden(p)).cloned().collect();
        folders.iter().any(|f| is_bop_scene(f)).then_some(folders)
    }

    /// Parses each scene folder's scene_camera.json and scene_gt.json, and categories.json in
    /// `dir`; the images' keys, in scene then image order.
    pub fn open(dir: &Path, scenes: &[PathBuf]) -> Result<(BopScenes, Vec<PathBuf>), SceneError> {
        let path = dir.join("categories.json");
        let listed = path.is_file().then(|| read_categories(&path)).transpose()?;
        let (names, guides) = match listed {
            Some((names, _, guides)) => (Some(names), guides),
            None => (None, BTreeMap::new()),
        };
        let models = match models_info_path(dir, is_bop_scene(dir)) {
            Some(path) => read_models_info(&path)?,
            None => BTreeMap::new(),
        };
        let parsed: Vec<Result<Vec<BopImage>, SceneError>> = scenes.par_iter().map(|s| scene_images(s)).collect();
        let mut images = BTreeMap::new();
        let mut keys = Vec::new();
        for scene in parsed {
            for image in scene? {
                let key = image.scene.join(format!("{:06}", image.im_id));
                keys.push(key.clone());
                images.insert(key, image);
            }
        }
        Ok((BopScenes { images, names, guides, models }, keys))
    }

    /// An obj_id's category: from categories.json, else `obj_<id>` as BOP names model files;
    /// with its model's box, the box's keypoints unless categories.json names others.
    fn category(&self, id: u32) -> Category {
        let listed = self.names.as_ref().and_then(|names| names.iter().find(|c| c.id == id));
        let category = listed.cloned().unwrap_or_else(|| {
            let name = format!("obj_{id:06}");
            Category::new(id, &name, "object")
        });
        match self.models.contains_key(&id) && category.keypoints.is_empty() {
            true => category.with_box_keypoints(),
            false => category,
        }
    }

    fn image(&self, key: &Path) -> Result<&BopImage, SceneError> {
        self.images.get(key).ok_or_else(|| SceneError::new(format!("{} is not a listed BOP image", key.display())))
    }
}

fn scene_name(scene: &Path) -> String {
    scene.file_name().map_or(scene.display().to_string(), |n| n.to_string_lossy().into_owned())
}

/// `why`, about the file `file` (relative to its scene folder) of scene `scene`.
fn refuse(scene: &Path, file: &str, why: impl std::fmt::Display) -> SceneError {
    SceneError::new(format!("scene {}: {file}: {why}", scene_name(scene)))
}

/// A scene's images, from its scene_camera.json (which lists them) and scene_gt.json.
fn scene_images(scene: &Path) -> Result<Vec<BopImage>, SceneError> {
    if !is_bop_scene(scene) {
        let missing = SCENE_FILES.iter().find(|f| !scene.join(f).is_file()).copied().unwrap_or_default();
        return Err(refuse(scene, missing, "missing; every scene folder of a BOP split holds it"));
    }
    let cameras: BTreeMap<String, CameraEntry> = read_json(scene, "scene_camera.json")?;
    let gts: BTreeMap<String, Vec<GtEntry>> = read_json(scene, "scene_gt.json")?;
    let gts: BTreeMap<u64, Vec<GtEntry>> = gts
        .into_iter()
        .map(|(k, v)| Ok((image_id(scene, "scene_gt.json", &k)?, v)))
        .collect::<Result<_, SceneError>>()?;
    let mut images = Vec::with_capacity(cameras.len());
    for (key, camera) in cameras {
        let im_id = image_id(scene, "scene_camera.json", &key)?;
        let at = |why: String| refuse(scene, "scene_camera.json", format!("image {im_id}: {why}"));
        let [fx, s, cx, z0, fy, cy, z1, z2, one] = camera.k[..] else {
            return Err(at(format!("cam_K has {} values, not 9 (3×3, row-major)", camera.k.len())));
        };
        if [s, z0, z1, z2] != [0.0; 4] || one != 1.0 || !(fx > 0.0 && fy > 0.0) {
            return Err(at(format!("cam_K {:?} is not [fx, 0, cx, 0, fy, cy, 0, 0, 1]", camera.k)));
        }
        let depth_scale = camera.depth_scale.ok_or_else(|| at("no depth_scale (mm per depth step)".into()))?;
        if !(depth_scale.is_finite() && depth_scale > 0.0) {
            return Err(at(format!("depth_scale {depth_scale} must be a positive number")));
        }
        let pose = match (&camera.r_w2c, &camera.t_w2c) {
            (Some(r), Some(t)) => world_from_camera(r, t).map_err(at)?,
            (None, None) => Pose::Unknown,
            _ => return Err(at("cam_R_w2c and cam_t_w2c come together".into())),
        };
        let listed = gts.get(&im_id).ok_or_else(|| {
            refuse(scene, "scene_gt.json", format!("image {im_id} (listed in scene_camera.json) is missing"))
        })?;
        let mut kept = Vec::with_capacity(listed.len());
        for (gt_id, gt) in listed.iter().enumerate() {
            let at = |why: &str| refuse(scene, "scene_gt.json", format!("image {im_id}, gt {gt_id}: {why}"));
            if gt.obj_id == 0 {
                return Err(at("obj_id 0; BOP's object ids start at 1"));
            }
            let (&[r00, r01, r02, r10, r11, r12, r20, r21, r22], &[t0, t1, t2]) = (&gt.r[..], &gt.t[..]) else {
                return Err(at("cam_R_m2c holds 9 values and cam_t_m2c 3"));
            };
            let r = [[r00, r01, r02], [r10, r11, r12], [r20, r21, r22]];
            kept.push(Gt { obj_id: gt.obj_id, pose: ObjectPose { r, t: [t0, t1, t2].map(|mm| mm / 1000.0) } });
        }
        images.push(BopImage {
            scene: scene.to_path_buf(),
            im_id,
            intrinsics: [fx, fy, cx, cy],
            depth_scale,
            pose,
            gts: kept,
        });
    }
    images.sort_by_key(|i| i.im_id);
    Ok(images)
}

fn read_json<T: serde::de::DeserializeOwned>(scene: &Path, file: &str) -> Result<T, SceneError> {
    let text = std::fs::read_to_string(scene.join(file)).map_err(|e| refuse(scene, file, e))?;
    serde_json::from_str(&text).map_err(|e| refuse(scene, file, format!("not BOP's format: {e}")))
}

fn image_id(scene: &Path, file: &str, key: &str) -> Result<u64, SceneError> {
    key.parse().map_err(|_| refuse(scene, file, format!("key `{key}` is not an image id")))
}

/// An image's files, relative to its scene folder.
fn depth_file(im_id: u64) -> String {
    format!("depth/{im_id:06}.png")
}

fn mask_file(im_id: u64, gt_id: usize) -> String {
    format!("mask_visib/{im_id:06}_{gt_id:06}.png")
}

/// A gt's amodal mask: its whole silhouette, hidden parts too.
fn amodal_file(im_id: u64, gt_id: usize) -> String {
    format!("mask/{im_id:06}_{gt_id:06}.png")
}

/// Whether the image's scene has amodal masks (then every gt has one).
fn has_amodal(image: &BopImage) -> bool {
    image.scene.join("mask").is_dir()
}

/// The render: rgb/ (PNG, else JPEG), else gray/.
fn render_file(image: &BopImage) -> Result<String, SceneError> {
    let candidates =
        ["rgb", "gray"].into_iter().flat_map(|d| ["png", "jpg"].map(|e| format!("{d}/{:06}.{e}", image.im_id)));
    candidates.clone().find(|f| image.scene.join(f).is_file()).ok_or_else(|| {
        let tried: Vec<String> = candidates.collect();
        bad(&tried[0], format!("missing (as are {})", tried[1..].join(", ")))
    })
}

/// A file's error, naming it relative to its scene folder.
fn file_error(im_id: u64, file: &str) -> impl Fn(vkdiff_formats::Error) -> SceneError {
    let file = file.to_string();
    move |e| match e {
        vkdiff_formats::Error::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound => {
            bad(&file, format!("missing (image {im_id} of scene_camera.json)"))
        }
        vkdiff_formats::Error::Io { source, .. } => bad(&file, source),
        vkdiff_formats::Error::Format { why, .. } => bad(&file, why),
        vkdiff_formats::Error::Tensor(why) => bad(&file, why),
    }
}

/// Refuses `file` of `size` where the image's depth (`depth/<im>.png`) is `depth`.
fn same_size(file: &str, size: (usize, usize), depth: (usize, usize)) -> Result<(), SceneError> {
    if size == depth {
        return Ok(());
    }
    let why = format!("{}×{}, its depth/ image is {}×{}", size.0, size.1, depth.0, depth.1);
    Err(bad(file, why))
}

impl SceneFormat for BopScenes {
    fn name(&self) -> &'static str {
        "bop"
    }

    fn scene_name(&self, key: &Path) -> String {
        let parent = key.parent().map(scene_name).unwrap_or_default();
        format!("{parent}/{}", scene_name(key))
    }

    fn index(&self, key: &Path) -> Result<SceneIndex, SceneError> {
        let image = self.image(key)?;
        let depth = depth_file(image.im_id);
        let (width, height, bits) =
            grey_png_size(&image.scene.join(&depth)).map_err(file_error(image.im_id, &depth))?;
        if bits != 16 {
            return Err(bad(&depth, format!("{bits}-bit; BOP's depth is 16-bit grey")));
        }
        let render = render_file(image)?;
        let size = image_size(&image.scene.join(&render)).map_err(file_error(image.im_id, &render))?;
        same_size(&render, size, (width, height))?;
        let amodal = has_amodal(image);
        let masks = (0..image.gts.len()).flat_map(|gt_id| {
            let visible = mask_file(image.im_id, gt_id);
            [Some(visible), amodal.then(|| amodal_file(image.im_id, gt_id))].into_iter().flatten()
        });
        for mask in masks {
            let (w, h, _) = grey_png_size(&image.scene.join(&mask)).map_err(file_error(image.im_id, &mask))?;
            same_size(&mask, (w, h), (width, height))?;
        }
        let mut used: Vec<u32> = image.gts.iter().map(|g| g.obj_id).collect();
        used.sort_unstable();
        used.dedup();
        Ok(SceneIndex {
            width: width as u32,
            height: height as u32,
            prompt: None,
            categories: used.into_iter().map(|id| self.category(id)).collect(),
            guides: self.guides.clone(),
        })
    }

    fn read(&self, key: &Path) -> Result<RawScene, SceneError> {
        let image = self.image(key)?;
        let depth_name = depth_file(image.im_id);
        let grey = read_grey_png(&image.scene.join(&depth_name)).map_err(file_error(image.im_id, &depth_name))?;
        let (width, height) = (grey.width, grey.height);
        // Steps of depth_scale mm to metres; 0 is no depth.
        let metres = image.depth_scale / 1000.0;
        let depth =
            grey.values.iter().map(|&v| if v == 0 { f32::INFINITY } else { (v as f64 * metres) as f32 }).collect();
        let mut labels = vec![0u32; width * height];
        let mut category_of = BTreeMap::new();
        let mut attributes = BTreeMap::new();
        let mut amodal = BTreeMap::new();
        for (gt_id, gt) in image.gts.iter().enumerate() {
            let mask = mask_file(image.im_id, gt_id);
            let visible = read_grey_png(&image.scene.join(&mask)).map_err(file_error(image.im_id, &mask))?;
            same_size(&mask, (visible.width, visible.height), (width, height))?;
            let label = gt_id as u32 + 1;
            for (p, _) in visible.values.iter().enumerate().filter(|(_, &v)| v != 0) {
                if labels[p] != 0 {
                    let (x, y) = (p % width, p / width);
                    let other = mask_file(image.im_id, labels[p] as usize - 1);
                    let why = format!("pixel ({x}, {y}) is also in {other}; BOP's visible masks do not overlap");
                    return Err(bad(&mask, why));
                }
                labels[p] = label;
            }
            category_of.insert(label, gt.obj_id);
            let mut carried = Map::from_iter([("obj_id".into(), json!(gt.obj_id)), ("gt_id".into(), json!(gt_id))]);
            carried.insert("pose".into(), gt.pose.to_json());
            if let Some(bbox) = self.models.get(&gt.obj_id) {
                carried.insert("bbox_3d".into(), bbox.to_json());
            }
            attributes.insert(label, carried);
            if has_amodal(image) {
                let file = amodal_file(image.im_id, gt_id);
                let whole = read_grey_png(&image.scene.join(&file)).map_err(file_error(image.im_id, &file))?;
                same_size(&file, (whole.width, whole.height), (width, height))?;
                let pixels: Vec<bool> = whole.values.iter().map(|&v| v != 0).collect();
                if let Some(mask) = AmodalMask::from_frame(&pixels, width) {
                    amodal.insert(label, mask);
                }
            }
        }
        let render = render_file(image)?;
        let shaded = read_image(&image.scene.join(&render)).map_err(file_error(image.im_id, &render))?;
        same_size(&render, (shaded.width, shaded.height), (width, height))?;
        let (width, height) = (width as u32, height as u32);
        let camera = Camera::from_intrinsics(width, height, image.intrinsics, image.pose.clone());
        Ok(RawScene {
            width,
            height,
            depth,
            labels,
            category_of,
            attributes,
            shaded: Some(shaded.pixels),
            normals: None,
            camera: Some(camera),
            amodal,
            ..RawScene::default()
        })
    }
}
