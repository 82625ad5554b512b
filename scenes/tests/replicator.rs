//! Replicator BasicWriter frames (tests/fixtures/scenes/replicator, written by
//! tools/make_replicator_fixtures.py as BasicWriter writes them) read as BasicWriter defines them,
//! each held to the fixture's own files read here (the PNGs with the png crate, the depth with
//! npyz, the JSON with serde_json): every whole frame one scene in frame order, the incomplete last
//! one skipped; each instance exactly the pixels of its colour, with its prim path and class;
//! BACKGROUND and UNLABELLED background; depth as written, inf background; K and the pose agreeing
//! with camera_params' matrices; each instance's 3D box, pose and projected corners as numpy
//! computed them (tests/fixtures/scenes/replicator-expected.json, by the same script); broken
//! frames refused naming the file.

mod common;

use common::{fixtures, json, refusal, When};
use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use vkdiff_render::camera::Pose;
use vkdiff_render::geometry::{Box3, Keypoint, ObjectPose, BOX_KEYPOINTS};
use vkdiff_scenes::{RenderedScenes, SceneSource, DEFAULT_FAR};

/// An RGBA PNG's pixels, as BasicWriter's mappings key them, and its width.
fn colours(path: &Path) -> (Vec<String>, usize) {
    let file = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let mut reader = png::Decoder::new(file).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgba);
    let keys =
        buf[..info.buffer_size()].chunks(4).map(|c| format!("({}, {}, {}, {})", c[0], c[1], c[2], c[3])).collect();
    (keys, info.width as usize)
}

fn npy(path: &Path) -> (Vec<f32>, Vec<u64>) {
    let file = npyz::NpyFile::new(std::fs::File::open(path).unwrap()).unwrap();
    let shape = file.shape().to_vec();
    (file.into_vec().unwrap(), shape)
}

/// The frames of a folder that have their semantics mapping, in order.
fn whole_frames(dir: &Path) -> Vec<String> {
    let mut frames: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| {
            let name = e.unwrap().file_name().to_string_lossy().into_owned();
            Some(name.strip_prefix("instance_segmentation_semantics_mapping_")?.strip_suffix(".json")?.to_string())
        })
        .collect();
    frames.sort();
    frames
}

const RESERVED: [&str; 2] = ["BACKGROUND", "UNLABELLED"];

/// Every class of the frames' semantics mappings, sorted.
fn classes(dir: &Path, frames: &[String]) -> Vec<String> {
    let mut all = BTreeSet::new();
    for f in frames {
        for v in
            json(&dir.join(format!("instance_segmentation_semantics_mapping_{f}.json"))).as_object().unwrap().values()
        {
            all.insert(v["class"].as_str().unwrap().to_string());
        }
    }
    all.into_iter().filter(|c| !RESERVED.contains(&c.as_str())).collect()
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}

#[test]
fn every_whole_frame_is_a_scene_with_its_masks_classes_depth_and_camera() {
    let dir = fixtures().join("replicator");
    let scenes = RenderedScenes::open(&dir, "object", DEFAULT_FAR).unwrap();
    let frames = whole_frames(&dir);
    let listed: Vec<&str> = (0..scenes.available().unwrap()).map(|k| scenes.scene(k).name.unwrap()).collect();
    assert_eq!(listed, frames, "the whole frames, in frame order");
    // The fixture's last frame has no semantics mapping: skipped, with a note naming it.
    let last = format!("{:04}", frames.len());
    assert!(dir.join(format!("rgb_{last}.png")).is_file());
    assert!(scenes.notes().iter().any(|n| n.contains(&format!("frame {last} skipped"))), "{:?}", scenes.notes());

    let names = classes(&dir, &frames);
    let categories = scenes.categories();
    let got: Vec<(u32, &str)> = categories.iter().map(|c| (c.id, c.name.as_str())).collect();
    let want: Vec<(u32, &str)> = names.iter().enumerate().map(|(k, n)| (k as u32 + 1, n.as_str())).collect();
    assert_eq!(got, want, "classes sorted by name, id 1 + index");
    let name_of: BTreeMap<u32, &str> = got.iter().copied().collect();

    let (mut instances, mut sky, mut unlabelled, mut cameras) = (0, 0, 0, 0);
    for (k, f) in frames.iter().enumerate() {
        let frame = scenes.frame(k as u64, 0).unwrap().frame;
        let (keys, width) = colours(&dir.join(format!("instance_segmentation_{f}.png")));
        assert_eq!((width, keys.len()), (frame.width as usize, frame.width as usize * frame.height as usize));
        let prims = json(&dir.join(format!("instance_segmentation_mapping_{f}.json")));
        let semantics = json(&dir.join(format!("instance_segmentation_semantics_mapping_{f}.json")));
        // Each pixel: background where its colour's class is reserved, else the instance of its
        // prim, of its class; one instance per prim.
        let mut id_of_prim: BTreeMap<String, u16> = BTreeMap::new();
        for (p, key) in keys.iter().enumerate() {
            let class = semantics[key]["class"].as_str().unwrap();
            let id = frame.ids[p];
            if RESERVED.contains(&class) {
                assert_eq!(id, 0, "frame {f}: pixel {p} is {class}");
                unlabelled += (class == "UNLABELLED") as usize;
                continue;
            }
            assert_ne!(id, 0, "frame {f}: pixel {p} is {key}");
            let prim = prims[key].as_str().unwrap();
            assert_eq!(*id_of_prim.entry(prim.to_string()).or_insert(id), id, "frame {f}: {prim} at pixel {p}");
            let instance = &frame.instances[id as usize - 1];
            assert_eq!(instance.attributes["prim_path"], prim, "frame {f}: pixel {p}");
            assert_eq!(name_of[&instance.category_id], class, "frame {f}: pixel {p}");
        }
        let distinct: BTreeSet<u16> = id_of_prim.values().copied().collect();
        assert_eq!((distinct.len(), frame.instances.len()), (id_of_prim.len(), id_of_prim.len()), "frame {f}");
        instances += frame.instances.len();
        // Depth as written; inf is background (+∞).
        let (depth, shape) = npy(&dir.join(format!("distance_to_image_plane_{f}.npy")));
        assert_eq!(shape, [frame.height as u64, frame.width as u64]);
        for (p, &z) in depth.iter().enumerate() {
            if z.is_finite() {
                assert_eq!(frame.depth[p], z, "frame {f}: pixel {p}");
            } else {
                assert_eq!(frame.depth[p], f32::INFINITY, "frame {f}: pixel {p}");
                sky += 1;
            }
        }
        // The camera: where camera_params is given, K projects camera points to the pixels
        // cameraProjection does, and the pose inverts cameraViewTransform.
        let params = dir.join(format!("camera_params_{f}.json"));
        let Some(c) = &frame.camera else {
            assert!(!params.is_file(), "frame {f}: camera_params but no camera");
            continue;
        };
        let params = json(&params);
        let (proj, view) = (floats(&params["cameraProjection"]), floats(&params["cameraViewTransform"]));
        let [w, h] = [0, 1].map(|i| params["renderProductResolution"][i].as_f64().unwrap());
        for point in [[0.3, -0.2, 2.0], [-0.5, 0.4, 3.5], [0.0, 0.0, 1.0]] {
            // OpenCV camera axes → USD's (y and z turned), through P (row vector), NDC → pixel
            // centres, rows from the top.
            let usd = [point[0], -point[1], -point[2], 1.0];
            let clip: Vec<f64> = (0..4).map(|j| (0..4).map(|i| usd[i] * proj[4 * i + j]).sum()).collect();
            let (x, y) = (clip[0] / clip[3], clip[1] / clip[3]);
            let (u, v) = ((x + 1.0) / 2.0 * w - 0.5, (1.0 - y) / 2.0 * h - 0.5);
            let (ku, kv) = (c.fx * point[0] / point[2] + c.cx, c.fy * point[1] / point[2] + c.cy);
            assert!((u - ku).abs() < 1e-9 && (v - kv).abs() < 1e-9, "frame {f}: ({u}, {v}) vs K's ({ku}, {kv})");
        }
        let Pose::Given(m) = &c.pose else { panic!("frame {f}: {:?}", c.pose) };
        for world in [[1.0, 2.0, 3.0], [-0.7, 0.1, 0.4]] {
            // World → camera by the view transform (row vector), USD axes → OpenCV's, then back
            // to the world by the pose.
            let row = [world[0], world[1], world[2], 1.0];
            let cam: Vec<f64> = (0..3).map(|j| (0..4).map(|i| row[i] * view[4 * i + j]).sum()).collect();
            let cv = [cam[0], -cam[1], -cam[2]];
            for i in 0..3 {
                let back: f64 = (0..3).map(|j| m[i][j] * cv[j]).sum::<f64>() + m[i][3];
                assert!((back - world[i]).abs() < 1e-9, "frame {f}: pose");
            }
        }
        cameras += 1;
    }
    assert!(instances >= 8 && sky > 0 && unlabelled > 0 && cameras >= 2, "{instances} {sky} {unlabelled} {cameras}");
}

/// A copy of the fixture's frames in a fresh folder, changed by `edit`.
fn copy_of(name: &str, edit: impl FnOnce(&Path)) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("vkdiff-replicator-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    for entry in std::fs::read_dir(fixtures().join("replicator")).unwrap() {
        let path = entry.unwrap().path();
        std::fs::copy(&path, dir.join(path.file_name().unwrap())).unwrap();
    }
    edit(&dir);
    dir
}

/// A copy of the fixture's frames with `categories` as its categories.json.
fn with_categories(name: &str, categories: &str) -> PathBuf {
    copy_of(name, |dir| std::fs::write(dir.join("categories.json"), categories).unwrap())
}

#[test]
fn categories_json_beside_the_frames_gives_the_ids_and_must_name_every_class() {
    let dir = fixtures().join("replicator");
    let names = classes(&dir, &whole_frames(&dir));
    // Ids in reverse name order: not what the sorted default gives.
    let listed: Vec<Value> = names
        .iter()
        .rev()
        .enumerate()
        .map(|(k, n)| serde_json::json!({"id": 10 + k, "name": n, "supercategory": "plant"}))
        .collect();
    let named = with_categories("named", &serde_json::json!({ "categories": listed }).to_string());
    let scenes = RenderedScenes::open(&named, "object", DEFAULT_FAR).unwrap();
    let got: Vec<(u64, String)> = scenes.categories().iter().map(|c| (c.id as u64, c.name.clone())).collect();
    let mut want: Vec<(u64, String)> =
        listed.iter().map(|c| (c["id"].as_u64().unwrap(), c["name"].as_str().unwrap().to_string())).collect();
    want.sort();
    assert_eq!(got, want);
    let frame = scenes.frame(0, 0).unwrap().frame;
    for instance in &frame.instances {
        let class = instance.attributes["class"].as_str().unwrap();
        assert_eq!(want.iter().find(|(_, n)| n == class).unwrap().0, instance.category_id as u64);
    }
    std::fs::remove_dir_all(&named).unwrap();

    let missing = &names[0];
    let partial = serde_json::json!({ "categories": [{"id": 1, "name": names[1], "supercategory": "x"}] });
    let short = with_categories("short", &partial.to_string());
    let e = RenderedScenes::open(&short, "object", DEFAULT_FAR).unwrap_err().to_string();
    assert!(e.contains(&format!("categories.json: names no category `{missing}`")) && !e.contains('\n'), "{e}");
    std::fs::remove_dir_all(&short).unwrap();
}

#[test]
fn broken_frames_are_refused_in_one_line_naming_the_file() {
    let bad = fixtures().join("replicator-bad");
    for (fault, when, needle) in [
        ("missing-semantics", When::Listed, "frame 0001: instance_segmentation_semantics_mapping_0001.json: missing"),
        ("depth-size", When::Listed, "scene 0001: rgb_0001.png: 80×60, the frame's depth is 79×60"),
        ("depth-dtype", When::Listed, "scene 0000: distance_to_image_plane_0000.npy: dtype <i4"),
        ("depth-3d", When::Listed, "scene 0000: distance_to_image_plane_0000.npy: shape [60, 80, 1]"),
        ("unknown-colour", When::Read, "scene 0000: instance_segmentation_0000.png: pixel (5, 30) is [1, 2, 3, 255]"),
        ("missing-box", When::Listed, "frame 0001: bounding_box_3d_0001.npy: missing; the other frames have 3D boxes"),
        (
            "box-dtype",
            When::Listed,
            "frame 0000: bounding_box_3d_0000.npy: dtype [semanticId <u4, x_min <f4, y_min <f4, z_min <f4, x_max <f4, \
             y_max <f4, z_max <f4, transform <f8 (4, 4), occlusionRatio <f4]; BasicWriter's bounding_box_3d rows are",
        ),
        (
            "mixed",
            When::Listed,
            "holds BlenderProc .hdf5 files and Replicator BasicWriter frames; one layout per folder",
        ),
    ] {
        let refused = refusal(&bad.join(fault), fault, when);
        assert!(refused.contains(needle), "{fault}: {refused}");
    }
}

fn close(got: &[f64], want: &Value, what: &str) {
    let want = floats(want);
    assert!(
        got.len() == want.len() && got.iter().zip(&want).all(|(a, b)| (a - b).abs() < 1e-9),
        "{what}: {got:?}, numpy {want:?}"
    );
}

#[test]
fn box_rows_give_their_instances_a_pose_a_bbox_3d_and_the_projected_corners() {
    let dir = fixtures().join("replicator");
    let expected = json(&fixtures().join("replicator-expected.json"));
    let scenes = RenderedScenes::open(&dir, "object", DEFAULT_FAR).unwrap();
    for category in scenes.categories() {
        assert_eq!(category.keypoints, BOX_KEYPOINTS.map(String::from), "{}", category.name);
        assert_eq!(category.skeleton.len(), 12);
    }
    let (mut boxed, mut bare, mut left_out, mut unposed, mut visibility) = (0, 0, 0, 0, [0; 3]);
    for k in 0..scenes.available().unwrap() {
        let name = scenes.scene(k).name.unwrap();
        let want = expected[name].as_object().unwrap();
        let frame = scenes.frame(k, 0).unwrap().frame;
        let prims: BTreeSet<&str> =
            frame.instances.iter().map(|i| i.attributes["prim_path"].as_str().unwrap()).collect();
        // The rows' prims that are instances are the ones numpy expects; the others are left out.
        let rows = json(&dir.join(format!("bounding_box_3d_prim_paths_{name}.json")));
        let rows: BTreeSet<&str> = rows.as_array().unwrap().iter().map(|p| p.as_str().unwrap()).collect();
        assert_eq!(
            rows.intersection(&prims).copied().collect::<BTreeSet<_>>(),
            want.keys().map(String::as_str).collect()
        );
        left_out += rows.difference(&prims).count();
        for instance in &frame.instances {
            let a = &instance.attributes;
            let prim = a["prim_path"].as_str().unwrap();
            let Some(w) = want.get(prim) else {
                assert!(!a.contains_key("bbox_3d") && !a.contains_key("pose"), "{name} {prim}: no row, no box");
                assert_eq!(instance.keypoints, [Keypoint::ABSENT; 9], "{name} {prim}");
                bare += 1;
                continue;
            };
            let bbox = Box3::of(a).unwrap();
            close(&bbox.min, &w["bbox_3d"]["min"], &format!("{name} {prim} min"));
            close(&bbox.max, &w["bbox_3d"]["max"], &format!("{name} {prim} max"));
            match ObjectPose::of(a) {
                Some(pose) => {
                    let r: Vec<f64> = pose.r.iter().flatten().copied().collect();
                    let want_r: Vec<Value> = w["pose"]["R"]
                        .as_array()
                        .unwrap()
                        .iter()
                        .flat_map(|row| row.as_array().unwrap().clone())
                        .collect();
                    close(&r, &Value::from(want_r), &format!("{name} {prim} R"));
                    close(&pose.t, &w["pose"]["t"], &format!("{name} {prim} t"));
                }
                None => {
                    assert!(w["pose"].is_null() && frame.camera.is_none(), "{name} {prim}: a pose where numpy has one");
                    unposed += 1;
                }
            }
            // numpy's to 1/100 pixel, as annotations.json writes them.
            let want = w["keypoints"].as_array().unwrap();
            assert_eq!(instance.keypoints.len(), want.len());
            for (got, p) in instance.keypoints.iter().zip(want) {
                let (x, y, v) = (p[0].as_f64().unwrap(), p[1].as_f64().unwrap(), p[2].as_u64().unwrap() as u8);
                let near = (got.x - x).abs() <= 0.005 + 1e-9 && (got.y - y).abs() <= 0.005 + 1e-9;
                assert!(near && got.v == v, "{name} {prim}: {got:?}, numpy {p}");
                visibility[v as usize] += 1;
            }
            boxed += 1;
        }
    }
    assert!(boxed >= 6 && bare >= 1 && left_out >= 1 && unposed >= 2, "{boxed} {bare} {left_out} {unposed}");
    assert!(visibility.iter().all(|&n| n > 0), "outside, hidden and seen corners: {visibility:?}");
}

#[test]
fn broken_box_files_are_refused_in_one_line_and_a_last_frame_without_them_skipped() {
    let edit_json = |dir: &Path, file: &str, value: Value| std::fs::write(dir.join(file), value.to_string()).unwrap();
    let prims = json(&fixtures().join("replicator/bounding_box_3d_prim_paths_0000.json"));
    let mut twice = prims.clone();
    twice[4] = twice[3].clone();
    let labels = "bounding_box_3d_labels_0000.json";
    for (fault, file, value, needle) in [
        (
            "short",
            "bounding_box_3d_prim_paths_0000.json",
            Value::from(prims.as_array().unwrap()[..4].to_vec()),
            "lists 4 prims; bounding_box_3d_0000.npy has 5 rows",
        ),
        ("twice", "bounding_box_3d_prim_paths_0000.json", twice, "lists /World/Apple_01 twice"),
        (
            "unlabelled",
            labels,
            serde_json::json!({"5": {"class": "leaf"}}),
            "no class for semanticId 3 (row 0, /World/Apple_07)",
        ),
        (
            "relabelled",
            labels,
            serde_json::json!({"3": {"class": "leaf"}, "5": {"class": "leaf"}}),
            "row 2 (/World/Apple_03) is `leaf`; the semantics mapping makes its instance `apple`",
        ),
    ] {
        let dir = copy_of(fault, |dir| edit_json(dir, file, value));
        let refused = refusal(&dir, fault, When::Listed);
        assert!(refused.contains(&format!("frame 0000: {file}: {needle}")), "{fault}: {refused}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
    // A last whole frame (0002, once 0003 is gone) without its rows: cut short, skipped.
    let cut = copy_of("cut", |dir| {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.to_string_lossy().contains("_0003.") {
                std::fs::remove_file(path).unwrap();
            }
        }
        std::fs::remove_file(dir.join("bounding_box_3d_0002.npy")).unwrap();
    });
    let scenes = RenderedScenes::open(&cut, "object", DEFAULT_FAR).unwrap();
    let listed: Vec<&str> = (0..scenes.available().unwrap()).map(|k| scenes.scene(k).name.unwrap()).collect();
    assert_eq!(listed, ["0000", "0001"]);
    assert!(
        scenes.notes().iter().any(|n| n.contains("frame 0002 skipped: bounding_box_3d_0002.npy")),
        "{:?}",
        scenes.notes()
    );
    std::fs::remove_dir_all(&cut).unwrap();
}
