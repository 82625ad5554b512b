//! Unity Perception SOLO datasets (tests/fixtures/scenes/solo, written by
//! tools/make_solo_fixtures.py as com.unity.perception 1.0's SOLO endpoint writes them) read as
//! Unity defines them, each held to the fixture's own files read here (the PNGs with the png
//! crate, the EXRs channel by channel with the exr crate, frame_data.json with serde_json): every
//! step's capture one scene in sequence then step order; each instance exactly the pixels of its
//! colour, with its instanceId and label; (0, 0, 0, 255) and (0, 0, 0, 0) background; depth as
//! written (Range made planar), 0 background; K against the projection matrix's own NDC mapping,
//! the pose against Unity's position and rotation; each 3D box converted, and every pixel of an
//! instance unprojected through K and the depth onto its box's surface; the stopped run's notes;
//! broken steps refused naming the file.

mod common;

use common::{fixtures, json, refusal, When};
use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use vkdiff_render::camera::Pose;
use vkdiff_render::geometry::BOX_KEYPOINTS;
use vkdiff_scenes::{RenderedScenes, SceneSource, SourceFrame, DEFAULT_FAR};

const INSTANCES: &str = "type.unity.com/unity.solo.InstanceSegmentationAnnotation";
const DEPTH: &str = "type.unity.com/unity.solo.DepthAnnotation";
const NORMALS: &str = "type.unity.com/unity.solo.NormalAnnotation";
const BOXES: &str = "type.unity.com/unity.solo.BoundingBox3DAnnotation";

/// An RGBA PNG's pixels and its width.
fn rgba(path: &Path) -> (Vec<[u8; 4]>, usize) {
    let file = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let mut reader = png::Decoder::new(file).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!((info.color_type, info.bit_depth), (png::ColorType::Rgba, png::BitDepth::Eight), "{path:?}");
    (buf[..info.buffer_size()].chunks(4).map(|c| [c[0], c[1], c[2], c[3]]).collect(), info.width as usize)
}

/// An EXR's channels by name, float32, row-major.
fn exr_channels(path: &Path) -> BTreeMap<String, Vec<f32>> {
    let image = exr::prelude::read_all_flat_layers_from_file(path).unwrap();
    let layer = &image.layer_data[0];
    layer
        .channel_data
        .list
        .iter()
        .map(|c| {
            let exr::prelude::FlatSamples::F32(v) = &c.sample_data else { panic!("{path:?}: not float32") };
            (c.name.to_string(), v.clone())
        })
        .collect()
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}

fn triple(v: &Value) -> [f64; 3] {
    floats(v).try_into().unwrap()
}

/// Unity's Quaternion * Vector3, q = (x, y, z, w): v + 2w(u×v) + 2u×(u×v).
fn turn(q: &[f64], v: [f64; 3]) -> [f64; 3] {
    let cross =
        |a: [f64; 3], b: [f64; 3]| [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    let u = [q[0], q[1], q[2]];
    let (a, b) = (cross(u, v), cross(u, cross(u, v)));
    std::array::from_fn(|i| v[i] + 2.0 * q[3] * a[i] + 2.0 * b[i])
}

fn close(a: f64, b: f64, eps: f64) -> bool {
    (a - b).abs() <= eps
}

/// A step's captures with an instance segmentation, as scenes: (name, the step's folder, its
/// frame_data, the capture).
fn listed(dir: &Path) -> Vec<(String, PathBuf, Value)> {
    let number = |p: &Path, prefix: &str, suffix: &str| -> Option<u64> {
        p.file_name()?.to_str()?.strip_prefix(prefix)?.strip_suffix(suffix)?.parse().ok()
    };
    let mut sequences: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_dir() && number(p, "sequence.", "").is_some())
        .collect();
    sequences.sort_by_key(|p| number(p, "sequence.", ""));
    let mut scenes = Vec::new();
    for sequence in sequences {
        let mut steps: Vec<PathBuf> = std::fs::read_dir(&sequence)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| number(p, "step", ".frame_data.json").is_some())
            .collect();
        steps.sort_by_key(|p| number(p, "step", ".frame_data.json"));
        for step in steps {
            let data = json(&step);
            let captures: Vec<&Value> = data["captures"]
                .as_array()
                .unwrap()
                .iter()
                .filter(|c| c["annotations"].as_array().unwrap().iter().any(|a| a["@type"] == INSTANCES))
                .collect();
            let base = format!(
                "{}/step{}",
                sequence.file_name().unwrap().to_str().unwrap(),
                number(&step, "step", ".frame_data.json").unwrap()
            );
            for c in &captures {
                let name = match captures.len() {
                    1 => base.clone(),
                    _ => format!("{base}.{}", c["id"].as_str().unwrap()),
                };
                scenes.push((name, sequence.clone(), (*c).clone()));
            }
        }
    }
    scenes
}

fn annotation<'a>(capture: &'a Value, kind: &str) -> Option<&'a Value> {
    capture["annotations"].as_array().unwrap().iter().find(|a| a["@type"] == kind)
}

#[test]
fn every_capture_is_a_scene_with_its_masks_labels_depth_camera_and_boxes() {
    let dir = fixtures().join("solo");
    let scenes = RenderedScenes::open(&dir, "object", DEFAULT_FAR).unwrap();
    let steps = listed(&dir);
    let names: Vec<&str> = (0..scenes.available().unwrap()).map(|k| scenes.scene(k).name.unwrap()).collect();
    let want: Vec<&str> = steps.iter().map(|s| s.0.as_str()).collect();
    assert_eq!(names, want, "each capture, in sequence and step order");
    assert!(names.contains(&"sequence.1/step0.camera2"), "{names:?}");
    assert!(scenes.notes().is_empty(), "{:?}", scenes.notes());

    // Categories: the labelIds and labelNames as given; every label with 3D boxes has the box's
    // keypoints.
    let mut labels = BTreeSet::new();
    for (_, _, capture) in &steps {
        for i in annotation(capture, INSTANCES).unwrap()["instances"].as_array().unwrap() {
            labels.insert((i["labelId"].as_u64().unwrap() as u32, i["labelName"].as_str().unwrap().to_string()));
        }
    }
    let categories = scenes.categories();
    let got: BTreeSet<(u32, String)> = categories.iter().map(|c| (c.id, c.name.clone())).collect();
    assert_eq!(got, labels);
    assert!(categories.iter().all(|c| c.keypoints == BOX_KEYPOINTS.map(String::from)), "{categories:?}");

    let (mut instances, mut sky, mut floor, mut transparent, mut boxed, mut cameras, mut ranged) =
        (0, 0, 0, 0, 0, 0, 0);
    for (k, (name, folder, capture)) in steps.iter().enumerate() {
        let SourceFrame { frame, shaded } = scenes.frame(k as u64, 0).unwrap();
        let (w, h) = (frame.width as usize, frame.height as usize);
        let seg = annotation(capture, INSTANCES).unwrap();
        let (pixels, width) = rgba(&folder.join(seg["filename"].as_str().unwrap()));
        assert_eq!((width, pixels.len()), (w, w * h), "{name}");
        let listed: BTreeMap<[u8; 4], &Value> = seg["instances"]
            .as_array()
            .unwrap()
            .iter()
            .map(|i| (floats(&i["color"]).iter().map(|&c| c as u8).collect::<Vec<_>>().try_into().unwrap(), i))
            .collect();
        // Each pixel: its colour's instance, with its instanceId, label and category; black
        // (either alpha) background.
        let mut id_of: BTreeMap<u64, u16> = BTreeMap::new();
        for (p, colour) in pixels.iter().enumerate() {
            let id = frame.ids[p];
            let Some(entry) = listed.get(colour) else {
                assert!(colour == &[0, 0, 0, 255] || colour == &[0, 0, 0, 0], "{name}: pixel {p} is {colour:?}");
                assert_eq!(id, 0, "{name}: pixel {p}");
                transparent += (colour[3] == 0) as usize;
                continue;
            };
            assert_ne!(id, 0, "{name}: pixel {p}");
            let unity = entry["instanceId"].as_u64().unwrap();
            assert_eq!(*id_of.entry(unity).or_insert(id), id, "{name}: instance {unity} at pixel {p}");
            let instance = &frame.instances[id as usize - 1];
            assert_eq!(instance.attributes["instance_id"], unity, "{name}: pixel {p}");
            assert_eq!(instance.attributes["label_name"], entry["labelName"], "{name}: pixel {p}");
            assert_eq!(instance.category_id as u64, entry["labelId"].as_u64().unwrap(), "{name}: pixel {p}");
        }
        assert_eq!(id_of.len(), frame.instances.len(), "{name}: one instance per listed colour shown");
        assert_eq!(id_of.values().collect::<BTreeSet<_>>().len(), id_of.len(), "{name}");
        instances += frame.instances.len();

        // The render, alpha dropped.
        let (rgb, _) = rgba(&folder.join(capture["filename"].as_str().unwrap()));
        assert_eq!(shaded.unwrap(), rgb.iter().flat_map(|c| [c[0], c[1], c[2]]).collect::<Vec<_>>(), "{name}");

        // The camera: K projects camera points where Unity's projection matrix (read column by
        // column) puts them, NDC [−1, 1] over the pixel edges, y up.
        let c = frame.camera.as_ref().expect("a perspective capture has a camera");
        let m = floats(&capture["matrix"]);
        let p = |r: usize, col: usize| m[3 * col + r];
        for [x, y, d] in [[0.3, -0.2, 2.0], [-0.5, 0.4, 3.5], [0.0, 0.0, 1.0]] {
            // OpenCV's (x, y, d) is Unity's view-space (x, −y, −d); clip w = d.
            let (vx, vy, vz) = (x, -y, -d);
            let (nx, ny) =
                ((p(0, 0) * vx + p(0, 1) * vy + p(0, 2) * vz) / d, (p(1, 0) * vx + p(1, 1) * vy + p(1, 2) * vz) / d);
            let (u, v) = ((nx + 1.0) / 2.0 * w as f64 - 0.5, (1.0 - ny) / 2.0 * h as f64 - 0.5);
            let (ku, kv) = (c.fx * x / d + c.cx, c.fy * y / d + c.cy);
            assert!(close(u, ku, 1e-9) && close(v, kv, 1e-9), "{name}: ({u}, {v}) vs K's ({ku}, {kv})");
        }
        // The pose: a world point seen from the camera (Unity: rotation⁻¹ · (p − position)), in
        // OpenCV's axes, goes back to Unity's world point with y negated.
        let Pose::Given(t) = &c.pose else { panic!("{name}: {:?}", c.pose) };
        let (position, rotation) = (triple(&capture["position"]), floats(&capture["rotation"]));
        let inverse = [-rotation[0], -rotation[1], -rotation[2], rotation[3]];
        for world in [[1.0, 2.0, 3.0], [-0.7, 0.1, 0.4]] {
            let local = turn(&inverse, std::array::from_fn(|i| world[i] - position[i]));
            let cv = [local[0], -local[1], local[2]];
            let back: Vec<f64> = (0..3).map(|i| (0..3).map(|j| t[i][j] * cv[j]).sum::<f64>() + t[i][3]).collect();
            let want = [world[0], -world[1], world[2]];
            assert!((0..3).all(|i| close(back[i], want[i], 1e-5)), "{name}: {back:?} vs {want:?}");
        }
        cameras += 1;

        // Depth: R as written (G = B = 0, A = 1 where drawn); 0 background. Range is made planar.
        let depth = annotation(capture, DEPTH).unwrap();
        let channels = exr_channels(&folder.join(depth["filename"].as_str().unwrap()));
        assert_eq!(channels.keys().collect::<Vec<_>>(), ["A", "B", "G", "R"], "{name}: Unity's RGBA");
        let range = depth["measurementStrategy"] == "Range";
        ranged += range as usize;
        for (p, &r) in channels["R"].iter().enumerate() {
            assert_eq!((channels["G"][p], channels["B"][p]), (0.0, 0.0), "{name}: pixel {p}");
            if r == 0.0 {
                assert_eq!((frame.depth[p], channels["A"][p]), (f32::INFINITY, 0.0), "{name}: pixel {p}");
                sky += 1;
                continue;
            }
            let (x, y) = (((p % w) as f64 - c.cx) / c.fx, ((p / w) as f64 - c.cy) / c.fy);
            let along = if range { (x * x + y * y + 1.0).sqrt() } else { 1.0 };
            assert!(close(frame.depth[p] as f64 * along, r as f64, 1e-5 * r as f64), "{name}: pixel {p}");
            floor += (frame.ids[p] == 0) as usize;
        }

        // 3D boxes: pose and bbox_3d converted (y negated), and every pixel of the instance, put
        // back in 3D through K and the depth, on its box's surface, facing the camera.
        let values = annotation(capture, BOXES).unwrap()["values"].as_array().unwrap();
        for value in values {
            let unity = value["instanceId"].as_u64().unwrap();
            let Some(&id) = id_of.get(&unity) else { continue };
            let a = &frame.instances[id as usize - 1].attributes;
            let (r, tv) = (&a["pose"]["R"], triple(&a["pose"]["t"]));
            let r: Vec<Vec<f64>> = r.as_array().unwrap().iter().map(floats).collect();
            let (translation, size, q) =
                (triple(&value["translation"]), triple(&value["size"]), floats(&value["rotation"]));
            assert_eq!(tv, [translation[0], -translation[1], translation[2]], "{name}: instance {unity}");
            for j in 0..3 {
                // Column j of R: the box's axis j (y negated in and out) in OpenCV's camera frame.
                let mut e = [0.0; 3];
                e[j] = if j == 1 { -1.0 } else { 1.0 };
                let axis = turn(&q, e);
                let want = [axis[0], -axis[1], axis[2]];
                assert!((0..3).all(|i| close(r[i][j], want[i], 1e-6)), "{name}: instance {unity}: R");
            }
            assert_eq!(a["bbox_3d"]["min"], serde_json::json!(size.map(|s| -s / 2.0)));
            assert_eq!(a["bbox_3d"]["max"], serde_json::json!(size.map(|s| s / 2.0)));
            let normals = frame.normals.as_ref();
            for p in (0..w * h).filter(|&p| frame.ids[p] == id) {
                let z = frame.depth[p] as f64;
                let cam = [((p % w) as f64 - c.cx) / c.fx * z, ((p / w) as f64 - c.cy) / c.fy * z, z];
                let local: Vec<f64> = (0..3).map(|j| (0..3).map(|i| r[i][j] * (cam[i] - tv[i])).sum()).collect();
                let out = (0..3).map(|i| local[i].abs() / (size[i] / 2.0)).fold(0.0, f64::max);
                assert!(close(out, 1.0, 2e-3), "{name}: instance {unity}: pixel {p} at {local:?}, box {size:?}");
                if let Some(n) = normals.map(|n| n[p]) {
                    // The face's normal: along one of the box's axes, toward the camera.
                    let along: Vec<f64> = (0..3).map(|j| (0..3).map(|i| r[i][j] * n[i] as f64).sum()).collect();
                    assert!(along.iter().any(|v| close(v.abs(), 1.0, 1e-4)), "{name}: pixel {p}: normal {n:?}");
                    assert!((0..3).map(|i| n[i] as f64 * cam[i]).sum::<f64>() < 0.0, "{name}: pixel {p}");
                }
            }
            boxed += 1;
        }
        assert_eq!(frame.normals.is_some(), annotation(capture, NORMALS).is_some(), "{name}");
    }
    assert!(instances >= 12 && boxed == instances, "{instances} instances, {boxed} boxes");
    assert!(
        sky > 0 && floor > 0 && transparent > 0 && cameras == steps.len() && ranged > 0,
        "{sky} {floor} {transparent} {ranged}"
    );
}

#[test]
fn a_stopped_run_is_read_as_far_as_it_is_written() {
    let dir = fixtures().join("solo-stopped");
    let scenes = RenderedScenes::open(&dir, "object", DEFAULT_FAR).unwrap();
    let names: Vec<&str> = (0..scenes.available().unwrap()).map(|k| scenes.scene(k).name.unwrap()).collect();
    assert_eq!(names, ["sequence.0/step0", "sequence.0/step1", "sequence.1/step0.camera", "sequence.1/step0.camera2"]);
    assert!(dir.join("sequence.1/step1.camera.png").is_file());
    let notes = scenes.notes().join("\n");
    assert!(notes.contains("sequence.1/step1 skipped: step1.frame_data.json is not written yet"), "{notes}");
    assert!(notes.contains("metadata.json is not there"), "{notes}");
    scenes.frame(3, 0).unwrap();
}

#[test]
fn a_sequence_folder_alone_is_its_steps() {
    let scenes = RenderedScenes::open(&fixtures().join("solo/sequence.0"), "object", DEFAULT_FAR).unwrap();
    let names: Vec<&str> = (0..scenes.available().unwrap()).map(|k| scenes.scene(k).name.unwrap()).collect();
    assert_eq!(names, ["sequence.0/step0", "sequence.0/step1"]);
}

/// A copy of the fixture's dataset in a fresh folder, with `categories` as its categories.json.
fn with_categories(name: &str, categories: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("vkdiff-solo-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let copy = |from: &Path, to: &Path| {
        std::fs::create_dir_all(to).unwrap();
        for entry in std::fs::read_dir(from).unwrap() {
            let path = entry.unwrap().path();
            if path.is_file() {
                std::fs::copy(&path, to.join(path.file_name().unwrap())).unwrap();
            }
        }
    };
    copy(&fixtures().join("solo"), &dir);
    for sequence in ["sequence.0", "sequence.1"] {
        copy(&fixtures().join("solo").join(sequence), &dir.join(sequence));
    }
    std::fs::write(dir.join("categories.json"), categories).unwrap();
    dir
}

#[test]
fn categories_json_beside_the_sequences_gives_the_ids_and_must_name_every_label() {
    let listed = serde_json::json!({"categories": [
        {"id": 7, "name": "Box", "supercategory": "thing"},
        {"id": 9, "name": "Crate", "supercategory": "thing", "keypoints": ["top"], "skeleton": []},
    ]});
    let named = with_categories("named", &listed.to_string());
    let scenes = RenderedScenes::open(&named, "object", DEFAULT_FAR).unwrap();
    let got: Vec<(u32, String, usize)> =
        scenes.categories().iter().map(|c| (c.id, c.name.clone(), c.keypoints.len())).collect();
    let want = [(7, "Box".to_string(), 9), (9, "Crate".to_string(), 1)];
    assert_eq!(got, want, "ids and keypoints as named; Box gets the box's");
    std::fs::remove_dir_all(&named).unwrap();

    let short = with_categories("short", &serde_json::json!({"categories": [{"id": 1, "name": "Crate"}]}).to_string());
    let e = RenderedScenes::open(&short, "object", DEFAULT_FAR).unwrap_err().to_string();
    assert!(e.contains("categories.json: names no category `Box`") && !e.contains('\n'), "{e}");
    std::fs::remove_dir_all(&short).unwrap();
}

#[test]
fn broken_steps_are_refused_in_one_line_naming_the_file() {
    let bad = fixtures().join("solo-bad");
    for (fault, when, needle) in [
        (
            "missing-png",
            When::Listed,
            "scene sequence.0/step1: step1.camera.instance segmentation.png: missing (step1.frame_data.json names it)",
        ),
        (
            "wrong-size",
            When::Listed,
            "scene sequence.0/step0: step0.camera.instance segmentation.png: 47×40, the depth is 48×40",
        ),
        (
            "unknown-colour",
            When::Read,
            "scene sequence.0/step0: step0.camera.instance segmentation.png: pixel (5, 30) is [1, 2, 3, 255], a colour",
        ),
        ("bad-json", When::Listed, "scene sequence.0/step1: step1.frame_data.json: not SOLO's frame data: EOF"),
        (
            "no-depth",
            When::Listed,
            "scene sequence.0/step0: step0.frame_data.json: capture `camera` has no DepthAnnotation",
        ),
        (
            "label-clash",
            When::Listed,
            "labelId 1 is `Crate` in sequence.0/step0 and `Barrel` in sequence.1/step0.camera",
        ),
        (
            "mixed",
            When::Listed,
            "holds BlenderProc .hdf5 files and Unity Perception SOLO sequences; one layout per folder",
        ),
    ] {
        let refused = refusal(&bad.join(fault), fault, when);
        assert!(refused.contains(needle), "{fault}: {refused}");
    }
}
