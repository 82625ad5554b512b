//! `vkdiff dataset audit --predictions` on Ultralytics' own output (tools/make_ultralytics_predictions.py,
//! ultralytics 8.4.190): `predict`'s save_txt labels, detect and segment, read back to the boxes
//! and polygons its Results objects held, in pixels on the set's ids; `val`'s save_json entries
//! mapped to the set's image and category ids; each audited through the command.

mod cli;

use cli::{scratch, vkdiff};
use serde_json::Value;
use std::path::{Path, PathBuf};
use vkdiff_dataset::{read_predictions, PredictionFormat, SetIndex};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/audit/ultralytics").join(name)
}

fn read_json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn numbers(v: &Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}

fn close(a: &[f64], b: &[f64], tolerance: f64) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tolerance)
}

#[test]
fn predict_labels_read_back_to_ultralytics_results() {
    let set = read_json(&fixture("set.json"));
    let index = SetIndex::of(&set);
    let id_of = |stem: &str| {
        set["images"].as_array().unwrap().iter().find(|i| i["file_name"] == format!("images/{stem}.png")).unwrap()["id"]
            .clone()
    };
    let expected = read_json(&fixture("expected.json"));
    for task in ["detect", "segment"] {
        let (read, format) = read_predictions(&fixture(&format!("{task}/labels")), None, &index).unwrap();
        assert_eq!(format, PredictionFormat::UltralyticsTxt);
        // Files are read by stem; Results came in the order predict was given the images.
        let mut want = expected[task].as_array().unwrap().clone();
        want.sort_by_key(|w| w["stem"].as_str().unwrap().to_string());
        let read = read.as_array().unwrap();
        assert!(!want.is_empty() && read.len() == want.len(), "{task}: {} read, {} expected", read.len(), want.len());
        for (k, (got, w)) in read.iter().zip(&want).enumerate() {
            assert_eq!(got["image_id"], id_of(w["stem"].as_str().unwrap()), "{task} {k}");
            assert_eq!(
                got["category_id"],
                set["categories"][w["class"].as_u64().unwrap() as usize]["id"],
                "{task} {k}"
            );
            // save_txt writes %g: six significant digits.
            assert!((got["score"].as_f64().unwrap() - w["conf"].as_f64().unwrap()).abs() < 1e-6, "{task} {k}");
            match w.get("polygon") {
                Some(polygon) => {
                    assert!(close(&numbers(&got["segmentation"][0]), &numbers(polygon), 0.01), "{task} {k}: {got} {w}");
                }
                None => {
                    let [x1, y1, x2, y2] = numbers(&w["xyxy"])[..] else { panic!() };
                    assert!(close(&numbers(&got["bbox"]), &[x1, y1, x2 - x1, y2 - y1], 0.01), "{task} {k}: {got} {w}");
                }
            }
        }
    }
}

#[test]
fn val_json_maps_to_the_sets_ids() {
    let set = read_json(&fixture("set.json"));
    for task in ["detect", "segment"] {
        let raw = read_json(&fixture(&format!("{task}/predictions.json")));
        let (read, format) =
            read_predictions(&fixture(&format!("{task}/predictions.json")), None, &SetIndex::of(&set)).unwrap();
        assert_eq!(format, PredictionFormat::UltralyticsJson);
        for (got, raw) in read.as_array().unwrap().iter().zip(raw.as_array().unwrap()) {
            let image = set["images"]
                .as_array()
                .unwrap()
                .iter()
                .find(|i| i["file_name"] == format!("images/{}", raw["file_name"].as_str().unwrap()))
                .unwrap();
            assert_eq!(
                (&got["image_id"], &got["category_id"]),
                (&image["id"], &set["categories"][0]["id"]),
                "{task}: {raw}"
            );
            assert_eq!(
                (&got["bbox"], &got["score"], &got["segmentation"]),
                (&raw["bbox"], &raw["score"], &raw["segmentation"])
            );
        }
    }
}

/// The set the predictions were made on, made again (the render is deterministic), audited with
/// each of Ultralytics' files.
#[test]
fn each_ultralytics_file_is_audited() {
    let root = scratch("audit-ultralytics");
    let dir = root.join("set");
    let out = vkdiff(&[
        "dataset",
        "--render-only",
        "--out",
        dir.to_str().unwrap(),
        "--seed",
        "11",
        "--crops",
        "0",
        "--count",
        "3",
        "--width",
        "320",
        "--height",
        "224",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let set = read_json(&fixture("set.json"));
    let made = read_json(&dir.join("annotations.json"));
    for (a, b) in made["images"].as_array().unwrap().iter().zip(set["images"].as_array().unwrap()) {
        assert_eq!((&a["id"], &a["file_name"], &a["width"]), (&b["id"], &b["file_name"], &b["width"]));
    }
    for (file, format, count) in [
        ("detect/labels", "ultralytics-txt", read_json(&fixture("expected.json"))["detect"].as_array().unwrap().len()),
        (
            "segment/labels",
            "ultralytics-txt",
            read_json(&fixture("expected.json"))["segment"].as_array().unwrap().len(),
        ),
        (
            "detect/predictions.json",
            "ultralytics-json",
            read_json(&fixture("detect/predictions.json")).as_array().unwrap().len(),
        ),
        (
            "segment/predictions.json",
            "ultralytics-json",
            read_json(&fixture("segment/predictions.json")).as_array().unwrap().len(),
        ),
    ] {
        let out = vkdiff(&[
            "dataset",
            "audit",
            dir.to_str().unwrap(),
            "--predictions",
            fixture(file).to_str().unwrap(),
            "--min-score",
            "0",
        ]);
        assert!(out.status.success(), "{file}: {}", String::from_utf8_lossy(&out.stderr));
        let settings = &read_json(&dir.join("audit.json"))["settings"];
        assert_eq!(
            (settings["predictions_format"].as_str(), settings["predictions_kept"].as_u64()),
            (Some(format), Some(count as u64)),
            "{file}"
        );
    }
    // A label file of an image the set does not have, and a class it does not have.
    let labels = root.join("labels");
    std::fs::create_dir_all(&labels).unwrap();
    for (name, line, message) in [
        ("000009.txt", "0 0.5 0.5 0.2 0.2 0.9", "no image 000009 in the set"),
        ("000000.txt", "3 0.5 0.5 0.2 0.2 0.9", "class 3, but the set has 1 categories"),
        ("000001.txt", "0 0.5 0.5 0.2 0.2", "predict with save_conf=True"),
    ] {
        std::fs::write(labels.join(name), line).unwrap();
        let out = vkdiff(&["dataset", "audit", dir.to_str().unwrap(), "--predictions", labels.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{name}: {err}");
        assert!(err.contains(message) && err.trim().lines().count() == 1, "{name}: {err}");
        std::fs::remove_file(labels.join(name)).unwrap();
    }
}
