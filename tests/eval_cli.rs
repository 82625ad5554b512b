//! `vkdiff eval` as a user runs it: pycocotools' statistics by name, F1 and mIoU, annotation
//! id 0, and one error line for bad input.

mod cli;

use cli::{scratch, vkdiff};
use serde_json::Value;

fn fixture(name: &str) -> String {
    format!("{}/tests/fixtures/eval/{name}", env!("CARGO_MANIFEST_DIR"))
}

fn eval_json(gt: &str, pred: &str) -> Value {
    let out = vkdiff(&["eval", "--gt", gt, "--pred", pred, "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn prints_pycocotools_statistics_f1_and_miou() {
    let got = eval_json(&fixture("gt.json"), &fixture("dt_segm.json"));
    let expected: Value = serde_json::from_str(&std::fs::read_to_string(fixture("expected.json")).unwrap()).unwrap();
    let stats = &expected["segm [1, 10, 100]"]["stats"];
    for (i, name) in
        ["AP", "AP50", "AP75", "APs", "APm", "APl", "AR1", "AR10", "AR100", "ARs", "ARm", "ARl"].iter().enumerate()
    {
        let (g, w) = (got[name].as_f64().unwrap(), stats[i].as_f64().unwrap());
        assert!((g - w).abs() <= 1e-6, "{name}: {g} against pycocotools {w}");
    }
    let (ap, ar, f1) = (got["AP"].as_f64().unwrap(), got["AR100"].as_f64().unwrap(), got["F1"].as_f64().unwrap());
    assert!((f1 - 2.0 * ap * ar / (ap + ar)).abs() < 1e-12);
}

/// mIoU, matched mIoU and foreground IoU against numpy over pycocotools' decoded masks, with
/// results that carry masks and results of which some are only boxes, at two score thresholds.
#[test]
fn mask_scores_are_those_numpy_computes_from_pycocotools_masks() {
    let expected: Value = serde_json::from_str(&std::fs::read_to_string(fixture("expected.json")).unwrap()).unwrap();
    for pred in ["dt_segm.json", "dt_mixed.json"] {
        let want = &expected["mask_scores"][pred];
        for threshold in ["0.5", "0.3"] {
            let out = vkdiff(&[
                "eval",
                "--gt",
                &fixture("gt.json"),
                "--pred",
                &fixture(pred),
                "--score-threshold",
                threshold,
                "--json",
            ]);
            assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
            let got: Value = serde_json::from_slice(&out.stdout).unwrap();
            for (name, key) in [
                ("mIoU", "mIoU".to_string()),
                ("mIoU_matched", "mIoU_matched".into()),
                ("foreground_IoU", format!("foreground_IoU@{threshold}")),
            ] {
                let (g, w) = (got[name].as_f64().unwrap(), want[&key].as_f64().unwrap());
                assert!((g - w).abs() <= 1e-12, "{pred} at {threshold}: {name} {g} against numpy {w}");
            }
        }
    }
}

#[test]
fn per_category_scores_are_pycocotools_per_category_slices() {
    let expected: Value = serde_json::from_str(&std::fs::read_to_string(fixture("expected.json")).unwrap()).unwrap();
    for (pred, iou, key) in
        [("dt_segm.json", "segm", "segm [1, 10, 100]"), ("dt_bbox.json", "bbox", "bbox [1, 10, 100]")]
    {
        let out = vkdiff(&["eval", "--gt", &fixture("gt.json"), "--pred", &fixture(pred), "--iou-type", iou, "--json"]);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let got: Value = serde_json::from_slice(&out.stdout).unwrap();
        let (got, want) = (got["per_category"].as_array().unwrap(), expected[key]["per_category"].as_array().unwrap());
        assert_eq!(got.len(), want.len(), "{key}: {got:?}");
        for (g, w) in got.iter().zip(want) {
            assert_eq!(g["id"], w["id"]);
            for name in ["AP", "AP50", "AR"] {
                let (g, w) = (g[name].as_f64().unwrap(), w[name].as_f64().unwrap());
                assert!((g - w).abs() <= 1e-6, "{key} category {}: {name} {g} against pycocotools {w}", w);
            }
        }
        assert_eq!((got[0]["name"].as_str(), got[1]["name"].as_str()), (Some("cap"), Some("stem")));
    }
    // Results of a category the ground truth does not list: one line naming both sets.
    let mut pred: Value = serde_json::from_str(&std::fs::read_to_string(fixture("dt_segm.json")).unwrap()).unwrap();
    pred[0]["category_id"] = 9.into();
    let path = cli::scratch("eval-categories").join("pred.json");
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(&path, pred.to_string()).unwrap();
    let out = vkdiff(&["eval", "--gt", &fixture("gt.json"), "--pred", path.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("category 9") && err.contains("1 (cap), 2 (stem)"), "{err}");
}

#[test]
fn detector_files_are_scored_by_box_areas_unless_area_from_mask() {
    let expected: Value = serde_json::from_str(&std::fs::read_to_string(fixture("expected.json")).unwrap()).unwrap();
    let stats = |args: &[&str]| {
        let out = vkdiff(
            &[&["eval", "--gt", &fixture("gt.json"), "--pred", &fixture("dt_both.json"), "--json"][..], args].concat(),
        );
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        serde_json::from_slice::<Value>(&out.stdout).unwrap()
    };
    for (args, key, area_from, rule) in [
        (vec![], "segm [1, 10, 100] both", "box", "loadres"),
        (vec!["--area-from", "mask"], "segm [1, 10, 100] both, boxes dropped", "mask", "mask"),
    ] {
        let got = stats(&args);
        assert_eq!((got["area_from"].as_str(), got["area_rule"].as_str()), (Some(area_from), Some(rule)));
        for (i, name) in ["AP", "APs", "APm", "APl"].iter().zip([0, 3, 4, 5]).map(|(n, i)| (i, n)) {
            let (g, w) = (got[name].as_f64().unwrap(), expected[key]["stats"][i].as_f64().unwrap());
            assert!((g - w).abs() <= 1e-6, "{key}: {name} {g} against pycocotools {w}");
        }
    }
}

#[test]
fn annotation_id_zero_is_matched_and_warned_about() {
    // The same ground truth with ids from 0 (as Roboflow exports them) scores the same.
    let mut gt: Value = serde_json::from_str(&std::fs::read_to_string(fixture("gt.json")).unwrap()).unwrap();
    for a in gt["annotations"].as_array_mut().unwrap() {
        a["id"] = (a["id"].as_u64().unwrap() - 1).into();
    }
    let path = scratch("eval-id0").join("gt.json");
    std::fs::write(&path, gt.to_string()).unwrap();
    let shifted = vkdiff(&["eval", "--gt", path.to_str().unwrap(), "--pred", &fixture("dt_segm.json"), "--json"]);
    assert!(
        String::from_utf8_lossy(&shifted.stderr).contains("annotation id 0"),
        "{}",
        String::from_utf8_lossy(&shifted.stderr)
    );
    let shifted: Value = serde_json::from_slice(&shifted.stdout).unwrap();
    assert_eq!(shifted, eval_json(&fixture("gt.json"), &fixture("dt_segm.json")));
}

#[test]
fn bad_input_is_one_error_line() {
    let dir = scratch("eval-bad");
    let bad = dir.join("bad.json");
    std::fs::write(
        &bad,
        r#"[{"image_id": 99, "category_id": 1, "segmentation": {"size": [90, 120], "counts": "00"}, "score": 0.5}]"#,
    )
    .unwrap();
    for (args, message) in [
        (vec!["--pred", bad.to_str().unwrap()], "image 99 is not in the ground truth"),
        (vec!["--pred", "/nonexistent.json"], "cannot read /nonexistent.json"),
        (vec!["--pred", &fixture("dt_segm.json"), "--max-dets", "10,1,100"], "positive and ascending"),
    ] {
        let out = vkdiff(&[&["eval", "--gt", &fixture("gt.json")][..], &args].concat());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains(message) && err.trim().lines().count() == 1, "{args:?}: {err}");
    }
}
