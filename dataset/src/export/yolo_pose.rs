//! Ultralytics' YOLO pose layout: the YOLO folders with a line `class cx cy w h x1 y1 v1 … xK yK
//! vK` per instance (the box from the COCO bbox, keypoints divided by the image's width and height
//! as Ultralytics' `convert_coco(use_keypoints=True)` divides them, v as COCO's 0, 1, 2) and
//! `kpt_shape: [K, 3]` in data.yaml, K the most keypoints any category names; a category with
//! fewer is padded with `0 0 0`, as an unlabelled keypoint is written.
//!
//! A separate format, not a column of the segmentation labels: Ultralytics reads one kind of label
//! per file (a pose line is not a polygon). data.yaml has no `flip_idx`: a left-right flip mirrors
//! the object, and which keypoint a mirrored one becomes depends on the object's own symmetry,
//! which the set does not know (for a 3D box's corners no relabelling makes a mirrored chiral
//! object a rotated one). Ultralytics then turns `fliplr` and `flipud` off by itself.

use super::set::FinishedSet;
use super::staging::Staging;
use super::yolo::{coordinate, write_layout, Layout};
use crate::error::{Error, Result};
use serde_json::Value;
use std::fmt::Write as _;

/// K, the most keypoints any of the set's categories names; a set without any is refused.
pub fn keypoints_per_line(set: &FinishedSet) -> Result<usize> {
    let categories = set.categories.as_array().into_iter().flatten();
    let most = categories.map(|c| c["keypoints"].as_array().map_or(0, Vec::len)).max().unwrap_or(0);
    if most == 0 {
        return Err(Error::Config(
            "the set's categories name no keypoints, so there is no pose to export: --format yolo gives its \
             segmentation labels"
                .into(),
        ));
    }
    Ok(most)
}

/// Writes the layout with `most` keypoints per line.
pub fn write(
    set: &FinishedSet,
    most: usize,
    staging: &mut Staging,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<()> {
    let mut line = |a: &Value, class: usize, width: f64, height: f64| -> Result<Option<String>> {
        let bad = |why: &str| Error::Config(format!("annotation {}: {why}", a["id"]));
        let bbox: [f64; 4] = serde_json::from_value(a["bbox"].clone()).map_err(|_| bad("its bbox is not 4 numbers"))?;
        let keypoints: Vec<f64> = match &a["keypoints"] {
            Value::Null => Vec::new(),
            k => serde_json::from_value(k.clone()).map_err(|_| bad("its keypoints are not numbers"))?,
        };
        if !keypoints.len().is_multiple_of(3) || keypoints.len() > 3 * most {
            return Err(bad(&format!("{} keypoint values, not x, y, v for up to {most} keypoints", keypoints.len())));
        }
        let [x, y, w, h] = bbox;
        let mut text = format!("{class}");
        for v in [(x + w / 2.0) / width, (y + h / 2.0) / height, w / width, h / height] {
            write!(text, " {}", coordinate(v)).expect("strings take writes");
        }
        for point in keypoints.chunks(3) {
            if ![0.0, 1.0, 2.0].contains(&point[2]) {
                return Err(bad(&format!("keypoint visibility {} is not COCO's 0, 1 or 2", point[2])));
            }
            let (px, py) = if point[2] > 0.0 { (point[0] / width, point[1] / height) } else { (0.0, 0.0) };
            write!(text, " {} {} {}", coordinate(px), coordinate(py), point[2]).expect("strings take writes");
        }
        text.push_str(&" 0 0 0".repeat(most - keypoints.len() / 3));
        Ok(Some(text))
    };
    let layout = Layout { task: "pose", extra_yaml: format!("kpt_shape: [{most}, 3]\n") };
    write_layout(set, staging, progress, &layout, &mut line)
}
