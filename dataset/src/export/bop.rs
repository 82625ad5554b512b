//! BOP's layout (bop_toolkit's docs/bop_datasets_format.md), the photoreal images in `rgb/`:
//!
//! ```text
//! models/models_info.json        each obj_id's 3D box (min_x/y/z, size_x/y/z, mm), where known
//! {train,val,test}/              a split, as BOP names them (no split type)
//!   categories.json              the set's categories (names, keypoints), which vkdiff's BOP reader reads
//!   {scene:06}/                  one of the set's scenes: its images (crops) in set order
//!     scene_camera.json          cam_K, depth_scale, cam_R_w2c and cam_t_w2c (mm) where known
//!     scene_gt.json              obj_id (the category), cam_R_m2c, cam_t_m2c (mm)
//!     scene_gt_info.json         bbox_obj, bbox_visib, px_count_all/valid/visib, visib_fract
//!     rgb/{im:06}.png            the image, linked
//!     depth/{im:06}.png          16-bit planar depth in depth_scale mm steps, 0 where none
//!     mask_visib/{im:06}_{gt:06}.png, mask/…  255 inside: the visible and the whole (amodal) mask
//! ```
//!
//! Every instance must have a pose; a set that has one without is refused before anything is
//! written.

use super::bop_image::{self, SceneFolder};
use super::bop_json::save_json;
use super::set::{FinishedSet, SetImage};
use super::splits::Split;
use super::staging::Staging;
use crate::error::{Error, Result};
use serde_json::{json, Value};
use std::collections::BTreeMap;
use vkdiff_render::geometry::{Box3, ObjectPose};

/// What a BOP export wrote, beyond the counts every export gives.
#[derive(Debug, Default, Clone, Copy)]
pub struct BopWritten {
    pub scene_folders: u64,
    /// Instances without an amodal mask: their silhouette in scene_gt_info.json is the visible mask.
    pub without_amodal: u64,
    /// Images whose depth did not fit 0.1 mm steps.
    pub coarse_depth: u64,
}

/// Writes the set, whose models' boxes are `boxes` ([`checked_models`]).
pub fn write(
    set: &FinishedSet,
    boxes: &BTreeMap<u64, Box3>,
    staging: &mut Staging,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<BopWritten> {
    let mut written = BopWritten::default();
    let mut done = 0;
    for split in set.splits() {
        let scenes = scenes_of(set, split);
        if scenes.is_empty() {
            continue;
        }
        let categories = json!({"categories": set.categories});
        let text = serde_json::to_string_pretty(&categories).expect("JSON values serialise") + "\n";
        staging.write(&format!("{}/categories.json", split.name()), text.as_bytes())?;
        for (k, images) in scenes.iter().enumerate() {
            let amodal = images.iter().all(|i| i.annotations.iter().all(|a| !a["amodal_segmentation"].is_null()));
            let scene = SceneFolder { path: format!("{}/{k:06}", split.name()), amodal };
            let (mut cameras, mut gts, mut infos) = (Vec::new(), Vec::new(), Vec::new());
            for (im_id, image) in images.iter().enumerate() {
                let bop = bop_image::write(set, image, &scene, im_id, staging)?;
                written.without_amodal += bop.without_amodal;
                written.coarse_depth += bop.coarse_depth as u64;
                cameras.push((im_id as u64, bop.camera));
                gts.push((im_id as u64, Value::from(bop.gts)));
                infos.push((im_id as u64, Value::from(bop.infos)));
                done += 1;
                progress(done, set.images.len());
            }
            for (file, entries) in [("scene_camera", cameras), ("scene_gt", gts), ("scene_gt_info", infos)] {
                staging.write(&format!("{}/{file}.json", scene.path), save_json(&entries).as_bytes())?;
            }
            written.scene_folders += 1;
        }
    }
    if !boxes.is_empty() {
        let models: Vec<(u64, Value)> = boxes.iter().map(|(&id, b)| (id, model_info(b))).collect();
        staging.write("models/models_info.json", save_json(&models).as_bytes())?;
    }
    Ok(written)
}

/// The split's images, by scene in the order the set first shows each.
fn scenes_of(set: &FinishedSet, split: Split) -> Vec<Vec<&SetImage>> {
    let mut order: Vec<u64> = Vec::new();
    let mut scenes: BTreeMap<u64, Vec<&SetImage>> = BTreeMap::new();
    for image in set.in_split(split) {
        if !scenes.contains_key(&image.scene_seed) {
            order.push(image.scene_seed);
        }
        scenes.entry(image.scene_seed).or_default().push(image);
    }
    order.iter().map(|seed| scenes.remove(seed).unwrap_or_default()).collect()
}

/// Refuses a set BOP cannot hold; else each obj_id's 3D box, where its instances give one.
pub fn checked_models(set: &FinishedSet) -> Result<BTreeMap<u64, Box3>> {
    check(set)?;
    model_boxes(set)
}

/// Every image has a camera K and every instance a pose, and an `obj_id` it carries is its
/// category's id (BOP's obj_id is the object's model, which the set's category names).
fn check(set: &FinishedSet) -> Result<()> {
    for image in &set.images {
        let id = &image.entry["id"];
        if serde_json::from_value::<[[f64; 3]; 3]>(image.entry["camera"]["K"].clone()).is_err() {
            return Err(Error::Config(format!(
                "image {id} ({}) has no camera K: BOP's scene_camera.json needs each image's cam_K",
                image.file_name()
            )));
        }
        for a in &image.annotations {
            if a.as_object().and_then(ObjectPose::of).is_none() {
                return Err(Error::Config(format!(
                    "annotation {} (image {id}, category {}) has no pose: BOP's scene_gt.json needs every \
                     instance's cam_R_m2c and cam_t_m2c, so only sets made from posed scenes (BOP) export as bop",
                    a["id"],
                    category_name(set, &a["category_id"])
                )));
            }
            if !a["obj_id"].is_null() && a["obj_id"] != a["category_id"] {
                return Err(Error::Config(format!(
                    "annotation {}: obj_id {} differs from its category {}; a BOP export writes the category as obj_id",
                    a["id"], a["obj_id"], a["category_id"]
                )));
            }
        }
    }
    Ok(())
}

fn category_name(set: &FinishedSet, id: &Value) -> String {
    let mut categories = set.categories.as_array().into_iter().flatten();
    categories.find(|c| &c["id"] == id).and_then(|c| c["name"].as_str()).unwrap_or("?").to_string()
}

/// Each obj_id's 3D box, from its instances' `bbox_3d`, which must agree: BOP's obj_id is one
/// rigid model.
fn model_boxes(set: &FinishedSet) -> Result<BTreeMap<u64, Box3>> {
    let mut boxes: BTreeMap<u64, Box3> = BTreeMap::new();
    for a in set.images.iter().flat_map(|i| &i.annotations) {
        let (Some(b), Some(id)) = (a.as_object().and_then(Box3::of), a["category_id"].as_u64()) else { continue };
        let known = *boxes.entry(id).or_insert(b);
        // A nanometre apart: one model's box, copied from one file, agrees exactly.
        let apart =
            known.min.iter().chain(&known.max).zip(b.min.iter().chain(&b.max)).any(|(p, q)| (p - q).abs() > 1e-9);
        if apart {
            return Err(Error::Config(format!(
                "annotation {}: its bbox_3d {:?}–{:?} differs from another of category {id} ({:?}–{:?}); BOP's obj_id \
                 is one model with one box",
                a["id"], b.min, b.max, known.min, known.max
            )));
        }
    }
    Ok(boxes)
}

/// models_info.json's entry: the box in mm (the model's diameter is unknown without its mesh).
fn model_info(b: &Box3) -> Value {
    let mm = |v: f64| v * 1000.0;
    json!({
        "min_x": mm(b.min[0]), "min_y": mm(b.min[1]), "min_z": mm(b.min[2]),
        "size_x": mm(b.max[0] - b.min[0]), "size_y": mm(b.max[1] - b.min[1]), "size_z": mm(b.max[2] - b.min[2]),
    })
}
