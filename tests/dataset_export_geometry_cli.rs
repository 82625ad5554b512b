//! The geometric labels through `vkdiff dataset export`, on render-only sets made from the BOP
//! dataset fixture (tests/fixtures/scenes/bop-dataset: poses, 3D boxes and so box keypoints,
//! amodal masks, cameras with world poses), whole frames and crops: the BOP export read back by
//! vkdiff's own BOP reader (`--scenes`) gives the set again, the COCO export keeps every label,
//! and each YOLO pose line holds its instance's box and keypoints. A set without poses or
//! keypoints is refused in one line.

mod cli;

use cli::{scratch, vkdiff};
use serde_json::Value;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use vkdiff_formats::image::read_depth_exr;

fn run_ok(args: &[&str]) {
    let out = vkdiff(args);
    assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
}

fn read_json(path: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// A render-only set of the fixture's BOP split, with `extra` flags (crops).
fn bop_set(dir: &Path, extra: &[&str]) -> PathBuf {
    let split = vkdiff_testkit::fixture("scenes/bop-dataset/train_pbr");
    let set = dir.join("set");
    let args =
        [&["dataset", "--render-only", "--scenes", split.to_str().unwrap(), "--out", set.to_str().unwrap()], extra];
    run_ok(&args.concat());
    set
}

fn export(set: &Path, out: &Path, format: &str, extra: &[&str]) {
    let args = ["dataset", "export", set.to_str().unwrap(), "--format", format, "--out", out.to_str().unwrap()];
    run_ok(&[&args[..], extra].concat());
}

fn numbers(v: &Value) -> Vec<f64> {
    match v {
        Value::Array(items) => items.iter().flat_map(numbers).collect(),
        Value::Object(map) => map.values().flat_map(numbers).collect(),
        Value::Number(n) => vec![n.as_f64().unwrap()],
        other => panic!("not numbers: {other}"),
    }
}

fn assert_close(a: &Value, b: &Value, tolerance: f64, what: &str) {
    let (a, b) = (numbers(a), numbers(b));
    assert_eq!(a.len(), b.len(), "{what}");
    assert!(a.iter().zip(&b).all(|(x, y)| (x - y).abs() <= tolerance), "{what}: {a:?} vs {b:?}");
}

/// The set's images by split as the BOP export lays them out: each split's scenes in the order
/// the set first shows them, each scene's images in set order; (split, scene, im) → image.
fn bop_layout(set: &Value, splits: &HashMap<u64, String>) -> HashMap<(String, usize, usize), Value> {
    let mut scenes: Vec<(String, u64)> = Vec::new();
    let mut layout = HashMap::new();
    for image in set["images"].as_array().unwrap() {
        let split = splits[&image["id"].as_u64().unwrap()].clone();
        let key = (split.clone(), image["scene_seed"].as_u64().unwrap());
        if !scenes.contains(&key) {
            scenes.push(key.clone());
        }
        let scene = scenes.iter().filter(|(s, _)| *s == split).position(|k| *k == key).unwrap();
        let im = layout.keys().filter(|(s, k, _): &&(String, usize, usize)| *s == split && *k == scene).count();
        layout.insert((split, scene, im), image.clone());
    }
    layout
}

/// Each image's split, from a COCO export of the same split flags.
fn splits_of(coco: &Path) -> HashMap<u64, String> {
    let mut splits = HashMap::new();
    for split in ["train", "val", "test"] {
        let Ok(bytes) = std::fs::read(coco.join(format!("{split}.json"))) else { continue };
        let file: Value = serde_json::from_slice(&bytes).unwrap();
        for image in file["images"].as_array().unwrap() {
            splits.insert(image["id"].as_u64().unwrap(), split.to_string());
        }
    }
    splits
}

/// The BOP export of a set, read back by `--scenes` (vkdiff's BOP reader) split by split, gives
/// the set's images, cameras, categories, poses (to the mm's rounding), visible and amodal masks
/// (exactly), boxes, 3D boxes and keypoints, and its depth to half a depth step.
fn assert_bop_round_trip(dir: &Path, set: &Path) {
    let flags = ["--val-fraction", "0.5", "--seed", "1"];
    let (bop, coco) = (dir.join("bop"), dir.join("coco"));
    export(set, &bop, "bop", &flags);
    export(set, &coco, "coco", &flags);
    let original = read_json(&set.join("annotations.json"));
    let layout = bop_layout(&original, &splits_of(&coco));
    let by_image = |coco: &Value, id: &Value| -> Vec<Value> {
        coco["annotations"].as_array().unwrap().iter().filter(|a| &a["image_id"] == id).cloned().collect()
    };
    let mut compared = 0;
    for split in ["train", "val"] {
        let back = dir.join(format!("back-{split}"));
        run_ok(&[
            "dataset",
            "--render-only",
            "--scenes",
            bop.join(split).to_str().unwrap(),
            "--out",
            back.to_str().unwrap(),
        ]);
        let read = read_json(&back.join("annotations.json"));
        assert_eq!(read["categories"], original["categories"], "{split}: categories");
        for image in read["images"].as_array().unwrap() {
            let (scene, im) = image["scene"].as_str().unwrap().split_once('/').unwrap();
            let key = (split.to_string(), scene.parse().unwrap(), im.parse().unwrap());
            let want = &layout[&key];
            let what = format!("{split}/{scene}/{im}");
            let rgb = bop.join(split).join(scene).join(format!("rgb/{im}.png"));
            assert!(
                std::fs::read(rgb).unwrap() == std::fs::read(set.join(want["file_name"].as_str().unwrap())).unwrap()
            );
            let (c, w) = (&image["camera"], &want["camera"]);
            assert_eq!((&c["K"], &c["width"], &c["height"]), (&w["K"], &w["width"], &w["height"]), "{what}");
            assert_close(&c["T_world_camera_opencv"], &w["T_world_camera_opencv"], 1e-12, &what);
            let (depth, _, _) = read_depth_exr(&back.join(image["depth_file"].as_str().unwrap())).unwrap();
            let (want_depth, _, _) = read_depth_exr(&set.join(want["depth_file"].as_str().unwrap())).unwrap();
            for (a, b) in depth.iter().zip(&want_depth) {
                assert!(a == b || (a - b).abs() <= 0.05e-3 + 1e-7, "{what}: depth {a} vs {b}");
            }
            let (got, expected) = (by_image(&read, &image["id"]), by_image(&original, &want["id"]));
            assert_eq!(got.len(), expected.len(), "{what}");
            for (gt, (a, b)) in got.iter().zip(&expected).enumerate() {
                for field in ["segmentation", "amodal_segmentation", "area", "amodal_area", "bbox", "amodal_bbox"] {
                    assert_eq!(a[field], b[field], "{what} gt {gt}: {field}");
                }
                for field in ["category_id", "obj_id", "mask_id", "iscrowd", "num_keypoints"] {
                    assert_eq!(a[field], b[field], "{what} gt {gt}: {field}");
                }
                assert!(b["amodal_segmentation"].is_object() && b["pose"].is_object(), "the fixture's labels");
                assert_eq!(a["gt_id"], gt, "gt ids count each image's instances");
                assert_eq!(a["pose"]["R"], b["pose"]["R"], "{what} gt {gt}");
                assert_close(&a["pose"]["t"], &b["pose"]["t"], 1e-12, &format!("{what} gt {gt} pose t"));
                assert_close(&a["bbox_3d"], &b["bbox_3d"], 1e-12, &format!("{what} gt {gt} bbox_3d"));
                let (ka, kb) = (numbers(&a["keypoints"]), numbers(&b["keypoints"]));
                for (p, q) in ka.chunks(3).zip(kb.chunks(3)) {
                    assert!(
                        p[2] == q[2] && (p[0] - q[0]).abs() <= 0.0101 && (p[1] - q[1]).abs() <= 0.0101,
                        "{p:?} {q:?}"
                    );
                }
                compared += 1;
            }
        }
    }
    let total = original["annotations"].as_array().unwrap().len();
    assert_eq!(compared, total, "every instance read back");
}

#[test]
fn bop_exports_of_whole_frames_and_crops_read_back_as_the_set() {
    let dir = scratch("export-bop-frames");
    assert_bop_round_trip(&dir, &bop_set(&dir, &[]));
    let dir = scratch("export-bop-crops");
    let set = bop_set(&dir, &["--crops", "3", "--crop-size", "48", "--seed", "3"]);
    let cut = read_json(&set.join("annotations.json"));
    let cut_amodal = cut["annotations"].as_array().unwrap().iter().filter(|a| a["amodal_area"] != a["area"]).count();
    assert!(cut_amodal > 0, "some instance is hidden in part: its amodal mask is more than its visible one");
    assert_bop_round_trip(&dir, &set);
}
