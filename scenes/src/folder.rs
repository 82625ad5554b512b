//! One scene folder, the format `vkdiff scene` writes and any renderer can:
//!
//! ```text
//! depth.exr        float depth, one channel (Z, <layer>.Depth.Z, V or R), larger is farther;
//!                  or depth.png (16-bit grey) with depth.json {"scale": s, "offset": o}: v·s + o,
//!                  and v = 0 is background
//! instances.png    8- or 16-bit grey: 0 background, k instance k (the depth's size)
//! categories.json  optional: {"categories": [{"id", "name", "supercategory"}, ...],
//!                             "instances": {"1": 1, "2": 3, ...}} (instance → category id)
//! shaded.png       optional: the renderer's image (img2img's start, a --render-only image)
//! prompt.txt       optional: this scene's prompt
//! ```

use crate::labels::RawScene;
use crate::SceneError;
use serde::Deserialize;
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use vkdiff_formats::image::read_depth_exr;
use vkdiff_formats::image::{read_grey_png, read_image};
use vkdiff_render::coco::Category;

/// A scene folder is one when it holds a depth file.
pub fn is_scene_folder(dir: &Path) -> bool {
    dir.join("depth.exr").is_file() || dir.join("depth.png").is_file()
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CategoriesFile {
    categories: Vec<Category>,
    #[serde(default)]
    instances: BTreeMap<String, u32>,
}

#[derive(Deserialize)]
struct DepthScale {
    scale: f64,
    #[serde(default)]
    offset: f64,
}

/// The categories of a `categories.json` (ids listed once, names given), and its instance map.
pub fn read_categories(path: &Path) -> Result<(Vec<Category>, BTreeMap<u32, u32>), SceneError> {
    let text = std::fs::read_to_string(path).map_err(|e| SceneError::io(path, e))?;
    let file: CategoriesFile = serde_json::from_str(&text)
        .map_err(|e| SceneError::file(path, format!("not JSON of the categories format: {e}")))?;
    let mut ids = BTreeSet::new();
    for c in &file.categories {
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
    Ok((file.categories, instances))
}

/// Reads the scene folder `dir`. Without categories.json every instance is `default` (id 1).
pub fn read_folder(dir: &Path, default: &Category) -> Result<(RawScene, Vec<Category>, Option<String>), SceneError> {
    let (depth, width, height) = read_depth(dir)?;
    let instances_path = dir.join("instances.png");
    let grey = read_grey_png(&instances_path).map_err(SceneError::from_file)?;
    if (grey.width, grey.height) != (width, height) {
        return Err(SceneError::file(
            &instances_path,
            format!("{}×{}, the depth is {width}×{height}", grey.width, grey.height),
        ));
    }
    let labels: Vec<u32> = grey.values.iter().map(|&v| v as u32).collect();
    let categories_path = dir.join("categories.json");
    let (categories, category_of) = if categories_path.is_file() {
        read_categories(&categories_path)?
    } else {
        let all: BTreeMap<u32, u32> = labels.iter().filter(|&&l| l != 0).map(|&l| (l, default.id)).collect();
        (vec![default.clone()], all)
    };
    let shaded_path = dir.join("shaded.png");
    let shaded = if shaded_path.is_file() {
        let image = read_image(&shaded_path).map_err(SceneError::from_file)?;
        if (image.width, image.height) != (width, height) {
            return Err(SceneError::file(
                &shaded_path,
                format!("{}×{}, the depth is {width}×{height}", image.width, image.height),
            ));
        }
        Some(image.pixels)
    } else {
        None
    };
    let prompt_path = dir.join("prompt.txt");
    let prompt = if prompt_path.is_file() {
        let text = std::fs::read_to_string(&prompt_path).map_err(|e| SceneError::io(&prompt_path, e))?;
        let text = text.trim().to_string();
        if text.is_empty() {
            return Err(SceneError::file(&prompt_path, "empty".into()));
        }
        Some(text)
    } else {
        None
    };
    let raw = RawScene {
        width: width as u32,
        height: height as u32,
        depth,
        labels,
        category_of,
        attributes: BTreeMap::new(),
        shaded,
    };
    Ok((raw, categories, prompt))
}

/// depth.exr, else depth.png scaled by depth.json.
fn read_depth(dir: &Path) -> Result<(Vec<f32>, usize, usize), SceneError> {
    let exr = dir.join("depth.exr");
    if exr.is_file() {
        return read_depth_exr(&exr).map_err(|e| SceneError::new(e.to_string()));
    }
    let (png, json) = (dir.join("depth.png"), dir.join("depth.json"));
    let text = std::fs::read_to_string(&json).map_err(|_| {
        SceneError::file(&json, "missing: depth.png needs it ({\"scale\": metres per step, \"offset\": 0})".into())
    })?;
    let scale: DepthScale = serde_json::from_str(&text)
        .map_err(|e| SceneError::file(&json, format!("not {{\"scale\", \"offset\"}}: {e}")))?;
    if !scale.scale.is_finite() || scale.scale <= 0.0 || !scale.offset.is_finite() {
        return Err(SceneError::file(&json, format!("scale {} must be a positive number", scale.scale)));
    }
    let grey = read_grey_png(&png).map_err(SceneError::from_file)?;
    if grey.bits != 16 {
        return Err(SceneError::file(&png, "8-bit; depth as PNG is 16-bit grey".into()));
    }
    let depth = grey
        .values
        .iter()
        .map(|&v| if v == 0 { f32::INFINITY } else { (v as f64 * scale.scale + scale.offset) as f32 })
        .collect();
    Ok((depth, grey.width, grey.height))
}
