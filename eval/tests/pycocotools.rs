//! `eval/` against pycocotools' COCOeval on fixtures from `tools/make_coco_eval_fixtures.py`
//! (pycocotools 2.0.10): the twelve statistics to 1e-6, the precision and recall arrays' sums,
//! and every polygon rasterised pixel for pixel as `frPyObjects` does.

use serde_json::Value;
use std::path::PathBuf;
use vkdiff_eval::{evaluate, polygon_rle, union, Dataset, EvalParams, IouType};
use vkdiff_render::rle::Rle;

fn fixture(name: &str) -> Value {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/eval").join(name);
    serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap()
}

fn check(iou_type: IouType, results: &str, max_dets: [usize; 3]) {
    let masks = iou_type == IouType::Segm;
    let gt = Dataset::ground_truth(&fixture("gt.json"), masks).unwrap();
    let dt = Dataset::results(&fixture(results), &gt, masks).unwrap();
    let stats = evaluate(&gt, &dt, &EvalParams { iou_type, max_dets }).unwrap();
    let kind = if masks { "segm" } else { "bbox" };
    let key = format!("{kind} {max_dets:?}");
    let want = &fixture("expected.json")[&key];
    for (i, (name, got)) in stats.names.iter().zip(&stats.values).enumerate() {
        // pycocotools reports AP at 100 detections whatever the caps; vkdiff at the last cap.
        let expected = if i == 0 && max_dets[2] != 100 { want["ap_at_last_max_dets"].as_f64() } else { want["stats"][i].as_f64() }.unwrap();
        assert!((got - expected).abs() <= 1e-6, "{key}: {name} = {got}, pycocotools {expected}");
    }
    let sum = |v: &[f64]| v.iter().sum::<f64>();
    for (what, got) in [("precision_sum", sum(&stats.precision)), ("recall_sum", sum(&stats.recall))] {
        let expected = want[what].as_f64().unwrap();
        assert!((got - expected).abs() <= 1e-9 * expected.abs().max(1.0), "{key}: {what} {got}, pycocotools {expected}");
    }
}

#[test]
fn segm_statistics_equal_pycocotools() {
    check(IouType::Segm, "dt_segm.json", [1, 10, 100]);
}

#[test]
fn bbox_statistics_equal_pycocotools() {
    check(IouType::Bbox, "dt_bbox.json", [1, 10, 100]);
}

#[test]
fn other_detection_caps_equal_pycocotools() {
    check(IouType::Segm, "dt_segm.json", [1, 3, 5]);
}

#[test]
fn polygons_rasterise_as_pycocotools_does() {
    let gt = fixture("gt.json");
    let (h, w) = (gt["images"][0]["height"].as_u64().unwrap() as u32, gt["images"][0]["width"].as_u64().unwrap() as u32);
    let expected = fixture("expected.json");
    let wanted = expected["polygon_rles"].as_array().unwrap();
    assert!(wanted.len() >= 5, "the fixture holds polygons");
    for want in wanted {
        let ann = gt["annotations"].as_array().unwrap().iter().find(|a| a["id"] == want["id"]).unwrap();
        let polys: Vec<Rle> = ann["segmentation"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| polygon_rle(&p.as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect::<Vec<_>>(), h, w))
            .collect();
        let got = union(&polys, h, w);
        let want = Rle::from_coco_string(want["counts"].as_str().unwrap(), h, w).unwrap();
        assert_eq!(got.to_mask(), want.to_mask(), "annotation {}", ann["id"]);
    }
}
