//! The geometric labels through `vkdiff dataset export`, on render-only sets made from the BOP
//! fixtures (tests/fixtures/scenes/bop-dataset: poses, 3D boxes and so box keypoints, amodal
//! masks, cameras with world poses; tests/fixtures/scenes/bop: named categories, a scene without
//! world poses, crops without instances), whole frames and crops: the BOP export read back by
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

/// A render-only set of a BOP fixture's split (`scenes/<split>` of the fixtures), with `extra`
/// flags (crops).
fn bop_set(dir: &Path, split: &str, extra: &[&str]) -> PathBuf {
    let split = vkdiff_testkit::fixture(&format!("scenes/{split}"));
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
        Value::Null => Vec::new(),
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
/// the set's images, cameras (world poses to a micrometre), categories, poses (to the mm's
/// rounding), visible and amodal masks (exactly), boxes, 3D boxes and keypoints, and its depth to
/// half a depth step.
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
            // To a micrometre: BOP stores world → camera, each way inverted by transposing R, and
            // write_bop's R is orthonormal only to Blender's single precision, so the centre moves
            // by up to |RRᵀ − I|·|centre| (5e-7 m in the fixture).
            assert_close(&c["T_world_camera_opencv"], &w["T_world_camera_opencv"], 1e-6, &what);
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
    assert_bop_round_trip(&dir, &bop_set(&dir, "bop-dataset/train_pbr", &[]));
    let dir = scratch("export-bop-crops");
    let set = bop_set(&dir, "bop-dataset/train_pbr", &["--crops", "3", "--crop-size", "48", "--seed", "3"]);
    let cut = read_json(&set.join("annotations.json"));
    let cut_amodal = cut["annotations"].as_array().unwrap().iter().filter(|a| a["amodal_area"] != a["area"]).count();
    assert!(cut_amodal > 0, "some instance is hidden in part: its amodal mask is more than its visible one");
    assert_bop_round_trip(&dir, &set);
}

/// Categories named by categories.json, cameras without a world pose, and crops without any
/// instance (an empty scene_gt list) come back too.
#[test]
fn bop_exports_without_world_poses_or_instances_read_back_as_the_set() {
    let dir = scratch("export-bop-split");
    let set = bop_set(&dir, "bop", &["--crops", "4", "--crop-size", "40", "--seed", "5"]);
    let coco = read_json(&set.join("annotations.json"));
    let images = coco["images"].as_array().unwrap();
    assert!(images.iter().any(|i| i["camera"]["T_world_camera_opencv"].is_null()), "a camera without a pose");
    let annotated = |i: &&Value| coco["annotations"].as_array().unwrap().iter().any(|a| a["image_id"] == i["id"]);
    assert!(!images.iter().all(|i| annotated(&i)), "a crop without instances");
    assert_eq!(coco["categories"][0]["name"], "duck");
    assert_bop_round_trip(&dir, &set);
}

/// The COCO split files hold the set's image entries (cameras too), annotations (keypoints,
/// poses, 3D boxes, amodal masks and all) and categories (keypoint names, skeletons) unchanged.
#[test]
fn coco_exports_keep_every_geometric_label() {
    let dir = scratch("export-coco-geometry");
    let set = bop_set(&dir, "bop-dataset/train_pbr", &["--crops", "2", "--crop-size", "48"]);
    let out = dir.join("coco");
    export(&set, &out, "coco", &["--val-fraction", "0.5"]);
    let original = read_json(&set.join("annotations.json"));
    let (mut images, mut annotations) = (Vec::new(), Vec::new());
    for split in ["train", "val"] {
        let file = read_json(&out.join(format!("{split}.json")));
        assert_eq!(file["categories"], original["categories"]);
        assert!(file["categories"][0]["keypoints"].as_array().unwrap().len() == 9, "box keypoints named");
        images.extend(file["images"].as_array().unwrap().iter().cloned());
        annotations.extend(file["annotations"].as_array().unwrap().iter().cloned());
    }
    let by_id = |list: &[Value]| -> HashMap<u64, Value> {
        list.iter().map(|v| (v["id"].as_u64().unwrap(), v.clone())).collect()
    };
    assert_eq!(by_id(&images), by_id(original["images"].as_array().unwrap()));
    assert_eq!(by_id(&annotations), by_id(original["annotations"].as_array().unwrap()));
    let fields = ["keypoints", "num_keypoints", "pose", "bbox_3d", "obj_id", "amodal_segmentation", "amodal_bbox"];
    assert!(annotations.iter().all(|a| fields.iter().all(|f| !a[f].is_null())), "every label is there");
    assert!(images.iter().all(|i| i["camera"]["K"].is_array()));
}

/// Each YOLO pose line: the class, the COCO box as centre and size over the image's sides, then
/// each keypoint's x and y over the width and height with its visibility (0 0 0 unlabelled);
/// data.yaml gives kpt_shape and no flip_idx.
#[test]
fn yolo_pose_lines_hold_each_box_and_keypoint() {
    let dir = scratch("export-yolo-pose");
    let set = bop_set(&dir, "bop-dataset/train_pbr", &["--crops", "3", "--crop-size", "48", "--seed", "3"]);
    let out = dir.join("yolo-pose");
    export(&set, &out, "yolo-pose", &["--val-fraction", "0"]);
    let yaml = std::fs::read_to_string(out.join("data.yaml")).unwrap();
    assert!(yaml.lines().any(|l| l == "kpt_shape: [9, 3]") && !yaml.contains("flip_idx"), "{yaml}");
    let coco = read_json(&set.join("annotations.json"));
    let mut lines = 0;
    let mut absent = 0;
    for image in coco["images"].as_array().unwrap() {
        let stem = image["file_name"].as_str().unwrap().trim_start_matches("images/").trim_end_matches(".png");
        let (w, h) = (image["width"].as_f64().unwrap(), image["height"].as_f64().unwrap());
        let text = std::fs::read_to_string(out.join(format!("labels/train/{stem}.txt"))).unwrap();
        let want: Vec<&Value> =
            coco["annotations"].as_array().unwrap().iter().filter(|a| a["image_id"] == image["id"]).collect();
        assert_eq!(text.lines().count(), want.len(), "{stem}: a line per instance");
        for (line, a) in text.lines().zip(want) {
            let v: Vec<f64> = line.split(' ').map(|t| t.parse().unwrap()).collect();
            assert_eq!(v.len(), 5 + 27, "{line}");
            assert_eq!(v[0], a["category_id"].as_f64().unwrap() - 1.0, "classes in the categories' order");
            let b = numbers(&a["bbox"]);
            let box_want = [(b[0] + b[2] / 2.0) / w, (b[1] + b[3] / 2.0) / h, b[2] / w, b[3] / h];
            assert!(box_want.iter().zip(&v[1..5]).all(|(p, q)| (p - q).abs() <= 5e-7), "{line}");
            for (p, q) in numbers(&a["keypoints"]).chunks(3).zip(v[5..].chunks(3)) {
                assert_eq!(p[2], q[2], "{line}");
                // The set's keypoint, to the line's 6 decimals (and at the edge within its pixel).
                let (x, y) = (p[0].clamp(0.0, w) / w, p[1].clamp(0.0, h) / h);
                assert!((x - q[0]).abs() <= 5e-7 && (y - q[1]).abs() <= 5e-7, "{p:?} {q:?}");
                absent += (q[2] == 0.0) as usize;
            }
            lines += 1;
        }
    }
    assert_eq!(lines, coco["annotations"].as_array().unwrap().len());
    assert!(absent > 0, "some keypoint falls outside its crop");
}

/// Exporting `set` (in `dir`) as `format` to `dir/out` fails with one error line holding
/// `message`, exit 2, and writes nothing beside the set.
fn assert_refused(dir: &Path, set: &Path, format: &str, message: &str) {
    let out = dir.join("out");
    let args = ["dataset", "export", set.to_str().unwrap(), "--format", format, "--out", out.to_str().unwrap()];
    let result = vkdiff(&args);
    let stderr = String::from_utf8_lossy(&result.stderr);
    let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error")).collect();
    assert_eq!(result.status.code(), Some(2), "{message}: {stderr}");
    assert!(errors.len() == 1 && errors[0].contains(message), "{message}: {stderr}");
    let left: Vec<_> = std::fs::read_dir(dir).unwrap().flatten().map(|e| e.file_name()).collect();
    assert_eq!(left, [set.file_name().unwrap()], "{message}: wrote {left:?}");
}

/// A set whose instances have no pose cannot be BOP gts, nor one without keypoints a pose set:
/// one line, exit 2, nothing written.
#[test]
fn sets_without_poses_or_keypoints_are_refused_in_one_line() {
    let dir = scratch("export-geometry-refused");
    let beds = dir.join("beds");
    let args = ["--render-only", "--count", "1", "--width", "160", "--height", "128", "--out"];
    run_ok(&[&["dataset"][..], &args, &[beds.to_str().unwrap()]].concat());
    for (format, message) in [
        ("bop", "has no pose: BOP's scene_gt.json needs every instance's cam_R_m2c and cam_t_m2c"),
        ("yolo-pose", "the set's categories name no keypoints"),
    ] {
        assert_refused(&dir, &beds, format, message);
    }
}

/// A BOP set edited to hold what BOP cannot: an image without a camera K, two boxes for one
/// obj_id, an obj_id that is not the category. One line each, exit 2, nothing written.
#[test]
fn bop_exports_refuse_cameras_boxes_and_objects_bop_cannot_hold() {
    let dir = scratch("export-bop-refused");
    let set = bop_set(&dir, "bop-dataset/train_pbr", &[]);
    let original = std::fs::read(set.join("annotations.json")).unwrap();
    type Edit = fn(&mut Value);
    let edits: [(Edit, &str); 3] = [
        (|c| c["images"][1]["camera"] = Value::Null, "image 2 (images/000001.png) has no camera K"),
        (|c| c["annotations"][4]["bbox_3d"]["max"][0] = 0.5.into(), "differs from another of category"),
        (|c| c["annotations"][0]["obj_id"] = 7.into(), "obj_id 7 differs from its category 1"),
    ];
    for (edit, message) in edits {
        let mut coco: Value = serde_json::from_slice(&original).unwrap();
        edit(&mut coco);
        std::fs::write(set.join("annotations.json"), serde_json::to_vec(&coco).unwrap()).unwrap();
        assert_refused(&dir, &set, "bop", message);
    }
}
