//! One scene folder, the format `vkdiff scene` writes and any renderer can:
//!
//! ```text
//! depth.exr        float depth, one channel (Z, <layer>.Depth.Z, V or R), larger is farther;
//!                  or depth.png (16-bit grey) with depth.json {"scale": s, "offset": o}: v·s + o,
//!                  and v = 0 is background
//! instances.png    8- or 16-bit grey: 0 background, k instance k (the depth's size)
//! categories.json  optional: {"categories": [{"id", "name", "supercategory"[, "prompt", "strength"]}, ...],
//!                             "instances": {"1": 1, "2": 3, ...}} (instance → category id)
//! shaded.png       optional: the renderer's image (img2img's start, a --render-only image)
//! normals.exr      optional: the renderer's normals, float channels X, Y, Z (the depth's size), in
//!                  the camera's frame with Blender's camera axes (x right, y up, z toward the
//!                  viewer), components in [-1, 1]; zero or non-finite where unknown
//! prompt.txt       optional: this scene's prompt
//! camera.json      optional: the camera, as `vkdiff scene` writes it (K, width, height, pose)
//! keypoints.json   optional: instance → its keypoints, COCO's flat x, y, v list
//! ```

use crate::folder_geometry::{check_keypoint_counts, read_camera, read_keypoints};
use crate::format::{SceneFormat, SceneIndex};
use crate::labels::{read_categories, CategoryMap, RawScene};
use crate::SceneError;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use vkdiff_formats::image::{
    depth_exr_size, grey_png_size, image_size, normals_exr_size, read_depth_exr, read_grey_png, read_image,
    read_normals_exr,
};
use vkdiff_render::coco::Category;

/// A scene folder is one when it holds a depth file.
pub fn is_scene_folder(dir: &Path) -> bool {
    dir.join("depth.exr").is_file() || dir.join("depth.png").is_file()
}

#[derive(Deserialize)]
struct DepthScale {
    scale: f64,
    #[serde(default)]
    offset: f64,
}

/// Scene folders: one folder per scene, in name order.
#[derive(Debug)]
pub struct SceneFolders {
    /// The category of every instance of a folder without categories.json (id 1).
    default: Category,
}

impl SceneFolders {
    pub fn new(default_category: &str) -> SceneFolders {
        let name = default_category.trim().to_string();
        SceneFolders { default: Category::new(1, &name, &name) }
    }

    /// The scene folders among `paths` (hidden ones skipped); None where there is none.
    pub fn find(paths: &[PathBuf]) -> Option<Vec<PathBuf>> {
        let folders: Vec<PathBuf> = paths.iter().filter(|p| p.is_dir() && !is_hidden(p)).cloned().collect();
        folders.iter().any(|f| is_scene_folder(f)).then_some(folders)
    }

    /// categories.json's categories and instance map, else the default category for every instance.
    fn categories(&self, dir: &Path) -> Result<Option<CategoryMap>, SceneError> {
        let path = dir.join("categories.json");
        path.is_file().then(|| read_categories(&path)).transpose()
    }
}

fn is_hidden(path: &Path) -> bool {
    path.file_name().is_some_and(|n| n.to_string_lossy().starts_with('.'))
}

impl SceneFormat for SceneFolders {
    fn name(&self) -> &'static str {
        "scene folders"
    }

    fn index(&self, dir: &Path) -> Result<SceneIndex, SceneError> {
        let (width, height) = depth_size(dir)?;
        let instances = dir.join("instances.png");
        let (w, h, _) = grey_png_size(&instances).map_err(SceneError::from_file)?;
        same_size(&instances, (w, h), (width, height))?;
        let shaded = dir.join("shaded.png");
        if shaded.is_file() {
            same_size(&shaded, image_size(&shaded).map_err(SceneError::from_file)?, (width, height))?;
        }
        let normals = dir.join("normals.exr");
        if normals.is_file() {
            same_size(&normals, normals_exr_size(&normals).map_err(SceneError::from_file)?, (width, height))?;
        }
        let (categories, instances, guides) = match self.categories(dir)? {
            Some(map) => map,
            None => (vec![self.default.clone()], Default::default(), Default::default()),
        };
        read_camera(dir, (width, height))?;
        let category_of = |id: u32| {
            let category_id = instances.get(&id).copied().unwrap_or(self.default.id);
            categories.iter().find(|c| c.id == category_id)
        };
        check_keypoint_counts(dir, &read_keypoints(dir)?, category_of)?;
        Ok(SceneIndex { width: width as u32, height: height as u32, prompt: read_prompt(dir)?, categories, guides })
    }

    fn read(&self, dir: &Path) -> Result<RawScene, SceneError> {
        let (depth, width, height) = read_depth(dir)?;
        let instances = dir.join("instances.png");
        let grey = read_grey_png(&instances).map_err(SceneError::from_file)?;
        same_size(&instances, (grey.width, grey.height), (width, height))?;
        let labels: Vec<u32> = grey.values.iter().map(|&v| v as u32).collect();
        let category_of = match self.categories(dir)? {
            Some((_, instances, _)) => instances,
            None => labels.iter().filter(|&&l| l != 0).map(|&l| (l, self.default.id)).collect(),
        };
        let shaded_path = dir.join("shaded.png");
        let shaded = if shaded_path.is_file() {
            let image = read_image(&shaded_path).map_err(SceneError::from_file)?;
            same_size(&shaded_path, (image.width, image.height), (width, height))?;
            Some(image.pixels)
        } else {
            None
        };
        let normals_path = dir.join("normals.exr");
        let normals = if normals_path.is_file() {
            let (normals, w, h) = read_normals_exr(&normals_path).map_err(SceneError::from_file)?;
            same_size(&normals_path, (w, h), (width, height))?;
            // Blender's camera axes (x right, y up, z toward the viewer) to OpenCV's.
            Some(normals.into_iter().map(|[x, y, z]| [x, -y, -z]).collect())
        } else {
            None
        };
        let (width, height) = (width as u32, height as u32);
        Ok(RawScene {
            width,
            height,
            depth,
            labels,
            category_of,
            attributes: BTreeMap::new(),
            shaded,
            normals,
            camera: read_camera(dir, (width as usize, height as usize))?,
            keypoints: read_keypoints(dir)?,
            ..RawScene::default()
        })
    }
}

/// Refuses the file `path` of `size` where the depth is `depth`.
fn same_size(path: &Path, size: (usize, usize), depth: (usize, usize)) -> Result<(), SceneError> {
    if size == depth {
        return Ok(());
    }
    Err(SceneError::file(path, format!("{}×{}, the depth is {}×{}", size.0, size.1, depth.0, depth.1)))
}

/// prompt.txt's text, trimmed; an empty one is refused.
fn read_prompt(dir: &Path) -> Result<Option<String>, SceneError> {
    let path = dir.join("prompt.txt");
    if !path.is_file() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&path).map_err(|e| SceneError::io(&path, e))?;
    let text = text.trim().to_string();
    if text.is_empty() {
        return Err(SceneError::file(&path, "empty".into()));
    }
    Ok(Some(text))
}

/// The depth's size from its header: depth.exr, else depth.png with its depth.json checked.
fn depth_size(dir: &Path) -> Result<(usize, usize), SceneError> {
    let exr = dir.join("depth.exr");
    if exr.is_file() {
        return depth_exr_size(&exr).map_err(SceneError::from_file);
    }
    let (png, _) = depth_png(dir)?;
    let (width, height, bits) = grey_png_size(&png).map_err(SceneError::from_file)?;
    sixteen_bits(&png, bits)?;
    Ok((width, height))
}

/// depth.png's path and depth.json's scale, checked.
fn depth_png(dir: &Path) -> Result<(PathBuf, DepthScale), SceneError> {
    let (png, json) = (dir.join("depth.png"), dir.join("depth.json"));
    let text = std::fs::read_to_string(&json).map_err(|_| {
        SceneError::file(&json, "missing: depth.png needs it ({\"scale\": metres per step, \"offset\": 0})".into())
    })?;
    let scale: DepthScale = serde_json::from_str(&text)
        .map_err(|e| SceneError::file(&json, format!("not {{\"scale\", \"offset\"}}: {e}")))?;
    if !scale.scale.is_finite() || scale.scale <= 0.0 || !scale.offset.is_finite() {
        return Err(SceneError::file(&json, format!("scale {} must be a positive number", scale.scale)));
    }
    Ok((png, scale))
}

/// Depth as a PNG is 16-bit grey.
fn sixteen_bits(png: &Path, bits: u8) -> Result<(), SceneError> {
    if bits == 16 {
        return Ok(());
    }
    Err(SceneError::file(png, "8-bit; depth as PNG is 16-bit grey".into()))
}

/// depth.exr, else depth.png scaled by depth.json.
fn read_depth(dir: &Path) -> Result<(Vec<f32>, usize, usize), SceneError> {
    let exr = dir.join("depth.exr");
    if exr.is_file() {
        return read_depth_exr(&exr).map_err(SceneError::from_file);
    }
    let (png, scale) = depth_png(dir)?;
    let grey = read_grey_png(&png).map_err(SceneError::from_file)?;
    sixteen_bits(&png, grey.bits)?;
    let depth = grey
        .values
        .iter()
        .map(|&v| if v == 0 { f32::INFINITY } else { (v as f64 * scale.scale + scale.offset) as f32 })
        .collect();
    Ok((depth, grey.width, grey.height))
}
