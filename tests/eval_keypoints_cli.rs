//! `vkdiff eval --iou-type keypoints` as a user runs it: pycocotools' ten keypoint statistics
//! (tools/make_coco_keypoint_fixtures.py) with the default, 1/k and given sigmas and other caps;
//! a set built from BOP scenes scored against its own keypoints; refusals in one line.

mod cli;

use cli::{scratch, vkdiff};
use serde_json::Value;
use std::path::Path;

fn fixture(name: &str) -> String {
    format!("{}/tests/fixtures/eval/keypoints/{name}", env!("CARGO_MANIFEST_DIR"))
}

fn eval_json(args: &[&str]) -> Value {
    let out = vkdiff(&[&["eval", "--iou-type", "keypoints", "--json"][..], args].concat());
    assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn keypoint_statistics_equal_pycocotools() {
    let expected: Value = serde_json::from_str(&std::fs::read_to_string(fixture("expected.json")).unwrap()).unwrap();
    for run in expected["runs"].as_array().unwrap() {
        let (gt, dt) = (fixture(run["gt"].as_str().unwrap()), fixture(run["dt"].as_str().unwrap()));
        let mut args = vec!["--gt".to_string(), gt, "--pred".into(), dt];
        let caps: Vec<String> = run["max_dets"].as_array().unwrap().iter().map(|c| c.to_string()).collect();
        args.extend(["--max-dets".into(), caps.join(",")]);
        if let Some(sigmas) = run["kpt_sigmas"].as_array() {
            let sigmas: Vec<String> = sigmas.iter().map(|s| s.to_string()).collect();
            args.extend(["--kpt-sigmas".into(), sigmas.join(",")]);
        }
        let got = eval_json(&args.iter().map(String::as_str).collect::<Vec<_>>());
        let tag = if caps == ["20"] { String::new() } else { format!("@{}", caps[caps.len() - 1]) };
        let names = ["AP", "AP50", "AP75", "APm", "APl", "AR", "AR50", "AR75", "ARm", "ARl"];
        for (name, want) in names.iter().zip(run["stats"].as_array().unwrap()) {
            let (g, w) = (got[format!("{name}{tag}")].as_f64(), want.as_f64().unwrap());
            assert!(g.is_some_and(|g| (g - w).abs() <= 1e-9), "{args:?}: {name}{tag} {g:?}, pycocotools {w}");
        }
        assert_eq!(got["kpt_sigmas"], run["used_sigmas"], "{args:?}");
        let (ap, ar) = (got[format!("AP{tag}")].as_f64().unwrap(), got[format!("AR{tag}")].as_f64().unwrap());
        assert!((got["F1"].as_f64().unwrap() - 2.0 * ap * ar / (ap + ar)).abs() < 1e-12, "{args:?}");
    }
}

/// A set rendered from BOP scenes (box keypoints from models_info.json) scored against its own
/// keypoints: every annotation with a labelled keypoint is found with OKS 1 (AP and AR 1), and
/// one with none (as a crop that cuts all of them off writes it) is left out, as pycocotools
/// leaves it.
#[test]
fn a_set_scored_against_its_own_keypoints_is_perfect() {
    let root = scratch("eval-keypoints-set");
    let set = root.join("set");
    let split = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/scenes/bop-dataset/train_pbr");
    let out =
        vkdiff(&["dataset", "--render-only", "--scenes", split.to_str().unwrap(), "--out", set.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let mut coco: Value =
        serde_json::from_str(&std::fs::read_to_string(set.join("annotations.json")).unwrap()).unwrap();
    // The first annotation as a crop that cut off all its keypoints writes it: unlabelled, and
    // so ignored ground truth, which must not count as missed.
    let first = &mut coco["annotations"][0];
    first["keypoints"] = Value::from(vec![0; 27]);
    first["num_keypoints"] = 0.into();
    let gt = root.join("gt.json");
    std::fs::write(&gt, coco.to_string()).unwrap();
    let labelled: Vec<&Value> =
        coco["annotations"].as_array().unwrap().iter().filter(|a| a["num_keypoints"].as_u64() > Some(0)).collect();
    assert!(labelled.len() >= 4, "{} annotations with keypoints", labelled.len());
    let results: Vec<Value> = labelled
        .iter()
        .map(|a| {
            serde_json::json!({"image_id": a["image_id"], "category_id": a["category_id"], "keypoints": a["keypoints"], "score": 0.9})
        })
        .collect();
    let pred = root.join("pred.json");
    std::fs::write(&pred, Value::from(results).to_string()).unwrap();
    let got = eval_json(&["--gt", gt.to_str().unwrap(), "--pred", pred.to_str().unwrap()]);
    for name in ["AP", "AP50", "AP75", "AR", "AR50", "AR75"] {
        assert_eq!(got[name].as_f64(), Some(1.0), "{name}: {got}");
    }
    assert_eq!(got["kpt_sigmas"].as_array().map(Vec::len), Some(9), "{got}");
}

#[test]
fn bad_keypoint_settings_are_one_error_line() {
    let (gt, dt) = (fixture("gt_9.json"), fixture("dt_9.json"));
    for (args, message) in [
        (vec!["--iou-type", "keypoints", "--kpt-sigmas", "0.1,0.1"], "has 9 keypoints where 2 are scored"),
        (vec!["--iou-type", "keypoints", "--area-from", "mask"], "--area-from mask is Detectron2's rule for segm"),
        (vec!["--iou-type", "bbox", "--kpt-sigmas", "0.1"], "--kpt-sigmas is for --iou-type keypoints"),
        (vec!["--iou-type", "bbox", "--max-dets", "20"], "--max-dets takes three numbers for --iou-type bbox"),
    ] {
        let out = vkdiff(&[&["eval", "--gt", &gt, "--pred", &dt][..], &args].concat());
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(message) && err.trim().lines().count() == 1, "{args:?}: {err}");
    }
}
