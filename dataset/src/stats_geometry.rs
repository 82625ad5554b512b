//! `dataset stats`' count of the geometric labels a renderer gave: keypoints by COCO visibility,
//! amodal masks and how much of each shape shows, 6D poses, 3D boxes and cameras.

use super::export::FinishedSet;
use serde_json::{json, Value};

pub fn geometry(set: &FinishedSet) -> Value {
    let annotations = || set.images.iter().flat_map(|i| &i.annotations);
    let with = |key: &str| annotations().filter(|a| !a[key].is_null()).count();
    // Keypoints by visibility: 0 not in the image, 1 hidden, 2 seen.
    let mut by_v = [0u64; 3];
    for a in annotations() {
        let flat = a["keypoints"].as_array().into_iter().flatten();
        for v in flat.skip(2).step_by(3).filter_map(Value::as_f64) {
            by_v[(v as usize).min(2)] += 1;
        }
    }
    let shown: Vec<f64> = annotations()
        .filter_map(|a| Some(a["area"].as_f64()? / a["amodal_area"].as_f64().filter(|&w| w > 0.0)?))
        .collect();
    json!({
        "keypoints": {
            "instances": with("keypoints"),
            "seen": by_v[2],
            "hidden": by_v[1],
            "not_in_image": by_v[0],
        },
        "amodal": {
            "instances": with("amodal_segmentation"),
            "occluded": shown.iter().filter(|&&f| f < 1.0).count(),
            "mean_visible_fraction": (!shown.is_empty()).then(|| shown.iter().sum::<f64>() / shown.len() as f64),
        },
        "poses": with("pose"),
        "boxes_3d": with("bbox_3d"),
        "images_with_camera": set.images.iter().filter(|i| i.entry["camera"]["K"].is_array()).count(),
    })
}
