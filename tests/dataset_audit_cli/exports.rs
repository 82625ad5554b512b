//! Exports after an audit: `--exclude-flagged` leaves out exactly the images it flagged, in every
//! format (dataset_audit_cli.rs plants the faults).

use super::cli::{scratch, tree, vkdiff};
use super::{as_result, export, planted, read_json, run_ok, Planted};
use serde_json::{json, Value};
use std::collections::BTreeSet;
use std::path::Path;

/// Exports `set` to `out` as `format`, leaving out the images the audit flagged `missing`.
fn export_without_missing(set: &Path, out: &Path, format: &str, val_fraction: &str) {
    let out = export(set, out, format, &["--exclude-flagged=missing", "--val-fraction", val_fraction]);
    assert!(out.status.success(), "export to {format}: {}", String::from_utf8_lossy(&out.stderr));
}

/// The stems of the images an export holds, however its format lists them.
fn exported_stems(out: &Path, format: &str) -> BTreeSet<String> {
    let stem =
        |name: &str| Path::new(name).file_stem().unwrap().to_string_lossy().split('.').next().unwrap().to_string();
    let files = tree(out).into_keys();
    match format {
        "coco" => ["train", "val"]
            .iter()
            .filter(|s| out.join(format!("{s}.json")).exists())
            .flat_map(|s| read_json(&out.join(format!("{s}.json")))["images"].as_array().unwrap().clone())
            .map(|i| stem(i["file_name"].as_str().unwrap()))
            .collect(),
        "yolo" | "yolo-pose" => files.filter(|f| f.starts_with("images/")).map(|f| stem(&f)).collect(),
        "hf" => files
            .filter(|f| f.ends_with("metadata.jsonl"))
            .flat_map(|f| std::fs::read_to_string(out.join(f)).unwrap().lines().map(String::from).collect::<Vec<_>>())
            .map(|line| stem(serde_json::from_str::<Value>(&line).unwrap()["file_name"].as_str().unwrap()))
            .collect(),
        "webdataset" => files
            .filter(|f| f.ends_with(".tar"))
            .flat_map(|f| {
                let list = std::process::Command::new("tar").arg("-tf").arg(out.join(f)).output().unwrap();
                String::from_utf8(list.stdout).unwrap().lines().map(String::from).collect::<Vec<_>>()
            })
            .map(|m| stem(&m))
            .collect(),
        "bop" => files.filter(|f| f.contains("/rgb/")).map(|f| f.replace("/rgb/", "/")).collect(),
        other => panic!("{other}"),
    }
}

/// Exports with `--exclude-flagged=KINDS` hold exactly the images the audit did not flag with
/// those kinds, in every format, and list the kept and dropped in excluded.json.
#[test]
fn exports_leave_out_exactly_the_flagged_images() {
    let root = scratch("audit-exports");
    let Planted { set, predictions, invented, .. } = planted(&root);
    run_ok(&["dataset", "audit", set.to_str().unwrap(), "--predictions", predictions.to_str().unwrap()]);
    let audit = read_json(&set.join("audit.json"));
    let stems_of = |ids: &dyn Fn(&Value) -> bool| -> BTreeSet<String> {
        let images = audit["images"].as_array().unwrap().iter().filter(|i| ids(i));
        images
            .map(|i| Path::new(i["file_name"].as_str().unwrap()).file_stem().unwrap().to_string_lossy().into_owned())
            .collect()
    };
    // Every image has some flag (a weak boundary, or a plant): leave out those missing objects.
    let missing = |i: &Value| i["flags"].as_array().unwrap().contains(&json!("missing"));
    let clean = stems_of(&|i| !missing(i));
    let flagged = stems_of(&missing);
    assert!(!clean.is_empty() && !flagged.is_empty(), "{clean:?} {flagged:?}");
    for format in ["coco", "yolo", "webdataset", "hf"] {
        let out_dir = root.join(format!("out-{format}"));
        export_without_missing(&set, &out_dir, format, "0.3");
        assert_eq!(exported_stems(&out_dir, format), clean, "{format}");
        let listed = read_json(&out_dir.join("excluded.json"));
        let names = |key: &str| -> BTreeSet<String> {
            let entries = listed[key].as_array().unwrap().iter();
            entries
                .map(|e| {
                    Path::new(e["file_name"].as_str().unwrap()).file_stem().unwrap().to_string_lossy().into_owned()
                })
                .collect()
        };
        assert_eq!((names("kept"), names("dropped")), (clean.clone(), flagged.clone()), "{format}: excluded.json");
    }
    // dataset stats reports what the audit flagged: what --exclude-flagged leaves out.
    let out = vkdiff(&["dataset", "stats", set.to_str().unwrap(), "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let stats: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(stats["audit"]["by_kind"]["missing"]["images"].as_u64(), Some(flagged.len() as u64));
    assert_eq!(stats["audit"]["flagged"], audit["summary"]["flagged"]);
    assert_eq!(stats["audit"]["covers_every_image"], true);
    // Only the invented detections' images.
    let out_dir = root.join("out-invented");
    let out = export(&set, &out_dir, "coco", &["--exclude-flagged=invented"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let dropped: BTreeSet<u64> = read_json(&out_dir.join("excluded.json"))["dropped"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| d["id"].as_u64().unwrap())
        .collect();
    assert_eq!(dropped, invented);
    // Every kind: nothing left, refused in one line.
    let out = export(&set, &root.join("none"), "coco", &["--exclude-flagged"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("is excluded: nothing to export") && !root.join("none").exists(), "{err}");
}

/// The geometric formats (yolo-pose, bop) on a set read from BOP scenes, one of whose objects
/// the predictions miss: its image is left out, the other kept.
#[test]
fn geometric_exports_leave_out_the_flagged_images() {
    let root = scratch("audit-geometric");
    let set = root.join("set");
    let scenes = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/scenes/bop-dataset/train_pbr");
    let out =
        vkdiff(&["dataset", "--render-only", "--scenes", scenes.to_str().unwrap(), "--out", set.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let coco = read_json(&set.join("annotations.json"));
    let results: Vec<Value> = coco["annotations"].as_array().unwrap()[1..].iter().map(as_result).collect();
    let predictions = root.join("predictions.json");
    std::fs::write(&predictions, Value::from(results).to_string()).unwrap();
    run_ok(&["dataset", "audit", set.to_str().unwrap(), "--predictions", predictions.to_str().unwrap()]);
    let missed_image = coco["annotations"][0]["image_id"].as_u64().unwrap();
    for format in ["yolo-pose", "bop"] {
        let out_dir = root.join(format);
        export_without_missing(&set, &out_dir, format, "0");
        let listed = read_json(&out_dir.join("excluded.json"));
        assert_eq!(listed["dropped"][0]["id"].as_u64(), Some(missed_image), "{format}");
        assert_eq!(listed["dropped"][0]["reasons"], json!(["missing"]), "{format}");
        let kept = listed["kept"].as_array().unwrap().len();
        assert_eq!(exported_stems(&out_dir, format).len(), kept, "{format}");
        assert_eq!(kept + 1, coco["images"].as_array().unwrap().len(), "{format}");
    }
}
