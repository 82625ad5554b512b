//! What every rendered scene becomes, whatever wrote it: depth with its background at +∞, and an
//! instance map whose ids (as the renderer numbered them, with gaps) become 1..K in ascending
//! order over the instances that show, each with its category; and the categories.json that
//! names categories and maps instances to them.

use crate::SceneError;
use serde::Deserialize;
use serde_json::{Map, Value};
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use vkdiff_render::camera::Camera;
use vkdiff_render::coco::Category;
use vkdiff_render::frame::{Frame, Instance};
use vkdiff_render::geometry::{box_keypoints, AmodalMask, Box3, Keypoint, ObjectPose, BOX_KEYPOINTS};

/// One scene as read from its files, before it becomes a [`Frame`].
#[derive(Default)]
pub struct RawScene {
    pub width: u32,
    pub height: u32,
    /// Depth (planar or along the ray), larger is farther.
    pub depth: Vec<f32>,
    /// The renderer's instance id per pixel; 0 is background.
    pub labels: Vec<u32>,
    /// Renderer id → category id; a category of 0 is background (BlenderProc's world).
    pub category_of: BTreeMap<u32, u32>,
    /// Renderer id → what its annotation records besides its mask (BlenderProc: the object's name).
    pub attributes: BTreeMap<u32, Map<String, Value>>,
    /// The renderer's own image, 8-bit RGB.
    pub shaded: Option<Vec<u8>>,
    /// The renderer's own normals, as [`Frame::normals`] holds them (camera space, OpenCV axes).
    pub normals: Option<Vec<[f32; 3]>>,
    /// The camera, where the format records it (BOP's `scene_camera.json`).
    pub camera: Option<Camera>,
    /// Renderer id → its keypoints, where the scene lists them (a scene folder's keypoints.json);
    /// instances of a category with a 3D box's keypoints get them from their `pose` and `bbox_3d`.
    pub keypoints: BTreeMap<u32, Vec<Keypoint>>,
    /// Renderer id → its whole shape, where the renderer gives it (BOP's `mask/`).
    pub amodal: BTreeMap<u32, AmodalMask>,
}

impl RawScene {
    /// The frame: depth at or past `far` (and NaN, infinite, zero or negative) is background;
    /// instances whose category is 0, or that have no pixel, are dropped. `categories` name each
    /// category's keypoints.
    pub fn into_frame(mut self, far: f32, categories: &[Category]) -> Result<(Frame, Option<Vec<u8>>), SceneError> {
        let n = (self.width as usize) * (self.height as usize);
        if self.depth.len() != n || self.labels.len() != n || self.normals.as_ref().is_some_and(|v| v.len() != n) {
            return Err(SceneError::new(format!(
                "the depth ({} values), the instance map ({} values) and the normals ({}) do not all hold its \
                 {}×{} pixels",
                self.depth.len(),
                self.labels.len(),
                self.normals.as_ref().map_or("none".into(), |v| format!("{} values", v.len())),
                self.width,
                self.height
            )));
        }
        let mut shown: BTreeMap<u32, u64> = BTreeMap::new();
        for &label in self.labels.iter().filter(|&&l| l != 0) {
            *shown.entry(label).or_default() += 1;
        }
        if let Some(label) = shown.keys().find(|l| !self.category_of.contains_key(l)) {
            return Err(SceneError::new(format!("instance {label} of the instance map has no category")));
        }
        let kept: Vec<u32> = shown.keys().copied().filter(|l| self.category_of[l] != 0).collect();
        if kept.len() > u16::MAX as usize - 1 {
            return Err(SceneError::new(format!("{} instances, more than a 16-bit mask holds (65534)", kept.len())));
        }
        let id_of: BTreeMap<u32, u16> = kept.iter().enumerate().map(|(k, &l)| (l, k as u16 + 1)).collect();
        let ids = self.labels.iter().map(|l| id_of.get(l).copied().unwrap_or(0)).collect();
        let background = |z: f32| !z.is_finite() || z <= 0.0 || z >= far;
        let depth: Vec<f32> = self.depth.into_iter().map(|z| if background(z) { f32::INFINITY } else { z }).collect();
        let instances = kept
            .iter()
            .map(|l| {
                let category = categories.iter().find(|c| c.id == self.category_of[l]);
                let attributes = self.attributes.remove(l).unwrap_or_default();
                let keypoints =
                    keypoints_of(category, &attributes, self.keypoints.remove(l), self.camera.as_ref(), &depth)
                        .map_err(|why| SceneError::new(format!("instance {l}: {why}")))?;
                Ok(Instance { category_id: self.category_of[l], attributes, keypoints, amodal: self.amodal.remove(l) })
            })
            .collect::<Result<_, SceneError>>()?;
        let (width, height, normals, camera) = (self.width, self.height, self.normals, self.camera);
        let frame = Frame { width, height, camera, depth, ids, instances, normals };
        Ok((frame, self.shaded))
    }
}

/// An instance's keypoints: those the scene lists, which must be as many as its category names;
/// else a 3D box's corners, where its category has them and the camera, pose and box are known;
/// else none.
fn keypoints_of(
    category: Option<&Category>,
    attributes: &Map<String, Value>,
    listed: Option<Vec<Keypoint>>,
    camera: Option<&Camera>,
    depth: &[f32],
) -> Result<Vec<Keypoint>, String> {
    let names = category.map_or(&[][..], |c| &c.keypoints[..]);
    if let Some(listed) = listed {
        if listed.len() != names.len() {
            return Err(format!("{} keypoints listed; its category names {}", listed.len(), names.len()));
        }
        return Ok(listed);
    }
    let boxed = !names.is_empty() && names.iter().zip(BOX_KEYPOINTS).all(|(n, b)| n == b);
    match (boxed, camera, ObjectPose::of(attributes), Box3::of(attributes)) {
        (true, Some(camera), Some(pose), Some(bbox)) => Ok(box_keypoints(camera, depth, &pose, &bbox)),
        _ => Ok(vec![Keypoint::ABSENT; names.len()]),
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CategoriesFile {
    categories: Vec<CategoryEntry>,
    #[serde(default)]
    instances: BTreeMap<String, u32>,
}

/// A category as categories.json lists it: COCO's fields, and how it is generated.
#[derive(Deserialize)]
struct CategoryEntry {
    #[serde(flatten)]
    category: Category,
    #[serde(flatten)]
    guide: CategoryGuide,
}

/// What categories.json may say of how a category's pixels are generated: the prompt SDXL sees
/// there, and how strongly the render is redrawn there.
#[derive(Clone, Debug, Default, PartialEq, Deserialize)]
pub struct CategoryGuide {
    #[serde(default)]
    pub prompt: Option<String>,
    #[serde(default)]
    pub strength: Option<f64>,
}

impl CategoryGuide {
    pub fn is_empty(&self) -> bool {
        self.prompt.is_none() && self.strength.is_none()
    }
}

/// A `categories.json`'s categories, its map of instance id → category id, and the guides it
/// gives categories, by id.
pub type CategoryMap = (Vec<Category>, BTreeMap<u32, u32>, BTreeMap<u32, CategoryGuide>);

/// The categories of a `categories.json` (ids listed once, names given), and its instance map.
pub fn read_categories(path: &Path) -> Result<CategoryMap, SceneError> {
    let text = std::fs::read_to_string(path).map_err(|e| SceneError::io(path, e))?;
    let file: CategoriesFile = serde_json::from_str(&text)
        .map_err(|e| SceneError::file(path, format!("not JSON of the categories format: {e}")))?;
    let mut ids = BTreeSet::new();
    let mut guides = BTreeMap::new();
    for CategoryEntry { category: c, guide } in &file.categories {
        if guide.prompt.as_ref().is_some_and(|p| p.trim().is_empty()) {
            return Err(SceneError::file(path, format!("category {}: its prompt is empty", c.id)));
        }
        if guide.strength.is_some_and(|s| !(s > 0.0 && s <= 1.0)) {
            return Err(SceneError::file(
                path,
                format!("category {}: strength {} is not in (0, 1]", c.id, guide.strength.unwrap_or_default()),
            ));
        }
        if !guide.is_empty() {
            guides.insert(c.id, guide.clone());
        }
        if !ids.insert(c.id) {
            return Err(SceneError::file(path, format!("category id {} is listed twice", c.id)));
        }
        if c.id == 0 || c.name.trim().is_empty() {
            return Err(SceneError::file(
                path,
                format!("category {}: ids start at 1 and every category needs a name", c.id),
            ));
        }
    }
    let mut instances = BTreeMap::new();
    for (key, &category) in &file.instances {
        let id: u32 = key.parse().map_err(|_| SceneError::file(path, format!("instance `{key}` is not a number")))?;
        if !ids.contains(&category) {
            return Err(SceneError::file(path, format!("instance {id} has category {category}, which is not listed")));
        }
        instances.insert(id, category);
    }
    Ok((file.categories.into_iter().map(|e| e.category).collect(), instances, guides))
}
