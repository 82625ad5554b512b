//! Kubric sequences (tests/fixtures/scenes/kubric, written by tools/make_kubric_fixtures.py with
//! Kubric's own file writers and post-processing) read as Kubric defines them, each held to the
//! fixture's own files read here (the segmentation's palette indices with the png crate,
//! metadata.json with serde_json, numpy's expected values from kubric-expected/): every frame of
//! every sequence one scene, in sequence then frame order; each instance exactly the pixels of its
//! index, with its instance_id, asset_id and category (its `category`, else its asset_id, else
//! `--category`); 0 background; the depth made planar as numpy makes it, and the renderer's Z
//! pass; the camera projecting world points where Kubric's own `project_point` puts them; every
//! pixel of an instance put back in 3D through K and the depth onto its box, its normal along a
//! box axis facing the camera; the stopped run's note; broken frames refused in one line.

mod common;

use common::{fixtures, json, refusal, When};
use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use vkdiff_render::camera::{Camera, Pose};
use vkdiff_render::geometry::BOX_KEYPOINTS;
use vkdiff_scenes::{RenderedScenes, SceneSource, SourceFrame, DEFAULT_FAR};

/// A PNG's samples as they are stored (palette indices, not colours), its width and its type.
fn png_samples(path: &Path) -> (Vec<u16>, usize, png::ColorType) {
    let mut decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    decoder.set_transformations(png::Transformations::IDENTITY);
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let samples = match info.bit_depth {
        png::BitDepth::Sixteen => {
            buf[..info.buffer_size()].chunks(2).map(|b| u16::from_be_bytes([b[0], b[1]])).collect()
        }
        _ => buf[..info.buffer_size()].iter().map(|&v| v as u16).collect(),
    };
    (samples, info.width as usize, info.color_type)
}

fn npy(path: &Path) -> Vec<f32> {
    npyz::NpyFile::new(std::fs::File::open(path).unwrap()).unwrap().into_vec::<f32>().unwrap()
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}

fn close(a: f64, b: f64, eps: f64) -> bool {
    (a - b).abs() <= eps
}

/// A world point in the camera's OpenCV frame: the inverse of `T_world_camera_opencv`.
fn to_camera(c: &Camera, p: [f64; 3]) -> [f64; 3] {
    let Pose::Given(t) = &c.pose else { panic!("{:?}", c.pose) };
    std::array::from_fn(|j| (0..3).map(|i| t[i][j] * (p[i] - t[i][3])).sum())
}

/// A world point's pixel, OpenCV's pixel centres.
fn project(c: &Camera, p: [f64; 3]) -> [f64; 2] {
    let x = to_camera(c, p);
    [c.fx * x[0] / x[2] + c.cx, c.fy * x[1] / x[2] + c.cy]
}

/// The sequences of a folder of them: (name, folder, metadata.json), in name order.
fn sequences(dir: &Path) -> Vec<(String, PathBuf, Value)> {
    let mut found: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.join("metadata.json").is_file())
        .collect();
    found.sort();
    found
        .into_iter()
        .map(|p| (p.file_name().unwrap().to_str().unwrap().to_string(), p.clone(), json(&p.join("metadata.json"))))
        .collect()
}

/// An instance's category name as the reader is to name it.
fn category_name(instance: &Value) -> String {
    instance["category"].as_str().or(instance["asset_id"].as_str()).unwrap_or("object").to_string()
}

#[test]
fn every_frame_is_a_scene_with_its_masks_categories_depth_camera_and_boxes() {
    let dir = fixtures().join("kubric");
    let expected = fixtures().join("kubric-expected");
    let projections = json(&expected.join("project.json"));
    let scenes = RenderedScenes::open(&dir, "object", DEFAULT_FAR).unwrap();
    assert!(scenes.notes().is_empty(), "{:?}", scenes.notes());
    let listed = sequences(&dir);
    let mut want = Vec::new();
    for (name, _, metadata) in &listed {
        for f in 0..metadata["metadata"]["num_frames"].as_u64().unwrap() {
            want.push(format!("{name}/{f:05}"));
        }
    }
    let names: Vec<&str> = (0..scenes.available().unwrap()).map(|k| scenes.scene(k).name.unwrap()).collect();
    assert_eq!(names, want, "each frame, in sequence and frame order");
    assert_eq!(names.len(), 5);

    // Categories: the instances' category names (else asset ids, else --category), ids in name
    // order; each with the box's keypoints, every instance having its bboxes_3d.
    let named: BTreeSet<String> =
        listed.iter().flat_map(|(_, _, m)| m["instances"].as_array().unwrap().iter().map(category_name)).collect();
    assert!(named.contains("Toys") && named.contains("cube") && named.contains("object"), "{named:?}");
    let id_of: BTreeMap<&str, u32> = named.iter().enumerate().map(|(k, n)| (n.as_str(), k as u32 + 1)).collect();
    let categories = scenes.categories();
    let got: Vec<(u32, &str)> = categories.iter().map(|c| (c.id, c.name.as_str())).collect();
    assert_eq!(got, id_of.iter().map(|(n, id)| (*id, *n)).collect::<Vec<_>>());
    assert!(categories.iter().all(|c| c.keypoints == BOX_KEYPOINTS.map(String::from)), "{categories:?}");

    let (mut sky, mut floor, mut shown, mut boxed_pixels, mut normals_checked, mut projected) = (0, 0, 0, 0, 0, 0);
    let mut k = 0;
    for (seq, folder, metadata) in &listed {
        let instances = metadata["instances"].as_array().unwrap();
        let [w, h] = [0, 1].map(|i| metadata["metadata"]["resolution"][i].as_u64().unwrap() as usize);
        for f in 0..metadata["metadata"]["num_frames"].as_u64().unwrap() as usize {
            let name = format!("{seq}/{f:05}");
            let SourceFrame { frame, shaded } = scenes.frame(k, 0).unwrap();
            k += 1;
            assert_eq!((frame.width as usize, frame.height as usize), (w, h), "{name}");

            // Each pixel: its index's instance (instances[index − 1]), 0 background.
            let (indices, width, colour) = png_samples(&folder.join(format!("segmentation_{f:05}.png")));
            assert_eq!(
                (width, indices.len(), colour),
                (w, w * h, png::ColorType::Indexed),
                "{name}: Kubric's palette PNG"
            );
            let mut id_of_index: BTreeMap<u16, u16> = BTreeMap::new();
            for (p, &index) in indices.iter().enumerate() {
                let id = frame.ids[p];
                if index == 0 {
                    assert_eq!(id, 0, "{name}: pixel {p}");
                    continue;
                }
                assert_ne!(id, 0, "{name}: pixel {p}");
                assert_eq!(*id_of_index.entry(index).or_insert(id), id, "{name}: index {index} at pixel {p}");
                let source = &instances[index as usize - 1];
                let instance = &frame.instances[id as usize - 1];
                assert_eq!(instance.attributes["instance_id"], index as u64, "{name}: pixel {p}");
                assert_eq!(instance.attributes.get("asset_id"), source.get("asset_id"), "{name}: pixel {p}");
                assert_eq!(instance.category_id, id_of[category_name(source).as_str()], "{name}: pixel {p}");
            }
            assert_eq!(id_of_index.len(), frame.instances.len(), "{name}: one instance per index shown");
            shown += frame.instances.len();

            // The render, alpha dropped.
            let (rgba, ..) = png_samples(&folder.join(format!("rgba_{f:05}.png")));
            let rgb: Vec<u8> = rgba.chunks(4).flat_map(|c| [c[0] as u8, c[1] as u8, c[2] as u8]).collect();
            assert_eq!(shaded.unwrap(), rgb, "{name}");

            // Depth: numpy's planar conversion of the TIFF, and the Z pass it was rendered from;
            // Blender's 1e10 (the sky) background.
            let planar = npy(&expected.join(seq).join(format!("planar_{f:05}.npy")));
            let z = npy(&expected.join(seq).join(format!("z_{f:05}.npy")));
            for p in 0..w * h {
                if z[p] >= 1e10 {
                    assert_eq!(frame.depth[p], f32::INFINITY, "{name}: pixel {p}");
                    assert_eq!(indices[p], 0, "{name}: pixel {p}");
                    sky += 1;
                    continue;
                }
                let (got, numpy, pass) = (frame.depth[p] as f64, planar[p] as f64, z[p] as f64);
                assert!(close(got, numpy, 1e-6 * numpy), "{name}: pixel {p}: {got} vs numpy's {numpy}");
                assert!(close(got, pass, 2e-6 * pass), "{name}: pixel {p}: {got} vs the Z pass {pass}");
                floor += (indices[p] == 0) as usize;
            }

            // The camera: world points land where Kubric's own project_point puts them
            // (normalised [0, 1]² from the image's corner: pixel centres at ·W − ½), and each
            // instance's centre at its image_positions.
            let c = frame.camera.as_ref().expect("every Kubric frame has its camera");
            let points = projections[seq]["points"].as_array().unwrap();
            for (point, at) in points.iter().zip(projections[seq]["frames"][f].as_array().unwrap()) {
                let p = project(c, floats(point).try_into().unwrap());
                let kubric = floats(at);
                let want = [kubric[0] * w as f64 - 0.5, kubric[1] * h as f64 - 0.5];
                assert!(close(p[0], want[0], 1e-6) && close(p[1], want[1], 1e-6), "{name}: {p:?} vs Kubric's {want:?}");
                projected += 1;
            }
            for source in instances {
                let centre: [f64; 3] = floats(&source["positions"][f]).try_into().unwrap();
                let at = floats(&source["image_positions"][f]);
                let p = project(c, centre);
                let want = [at[0] * w as f64 - 0.5, at[1] * h as f64 - 0.5];
                assert!(close(p[0], want[0], 1e-4) && close(p[1], want[1], 1e-4), "{name}: {p:?} vs {want:?}");
            }

            // Boxes: every pixel of an instance, put back in 3D through K and the planar depth and
            // into the object's frame by its pose, lies on its bbox_3d's surface; where normals
            // are written, each is along one of the box's axes and faces the camera.
            assert_eq!(frame.normals.is_some(), folder.join(format!("normal_{f:05}.png")).is_file(), "{name}");
            for (&index, &id) in &id_of_index {
                let a = &frame.instances[id as usize - 1].attributes;
                let r: Vec<Vec<f64>> = a["pose"]["R"].as_array().unwrap().iter().map(floats).collect();
                let t = floats(&a["pose"]["t"]);
                let (min, max) = (floats(&a["bbox_3d"]["min"]), floats(&a["bbox_3d"]["max"]));
                for p in (0..w * h).filter(|&p| frame.ids[p] == id) {
                    let d = frame.depth[p] as f64;
                    let cam = [((p % w) as f64 - c.cx) / c.fx * d, ((p / w) as f64 - c.cy) / c.fy * d, d];
                    let local: Vec<f64> = (0..3).map(|j| (0..3).map(|i| r[i][j] * (cam[i] - t[i])).sum()).collect();
                    let out = (0..3)
                        .map(|i| (local[i] - (min[i] + max[i]) / 2.0).abs() / ((max[i] - min[i]) / 2.0))
                        .fold(0.0, f64::max);
                    assert!(
                        close(out, 1.0, 2e-3),
                        "{name}: index {index}: pixel {p} at {local:?}, box {min:?} {max:?}"
                    );
                    boxed_pixels += 1;
                    if let Some(n) = frame.normals.as_ref().map(|n| n[p]) {
                        let along: Vec<f64> = (0..3).map(|j| (0..3).map(|i| r[i][j] * n[i] as f64).sum()).collect();
                        assert!(along.iter().any(|v| close(v.abs(), 1.0, 1e-3)), "{name}: pixel {p}: normal {n:?}");
                        assert!((0..3).map(|i| n[i] as f64 * cam[i]).sum::<f64>() < 0.0, "{name}: pixel {p}");
                        normals_checked += 1;
                    }
                }
            }
            if let Some(normals) = &frame.normals {
                assert!((0..w * h).filter(|&p| z[p] >= 1e10).all(|p| normals[p] == [0.0; 3]), "{name}: the sky's");
            }
        }
    }
    assert!(shown >= 15 && boxed_pixels >= 800 && normals_checked > 0, "{shown} {boxed_pixels} {normals_checked}");
    assert!(sky > 0 && floor > 0 && projected == 20, "{sky} {floor} {projected}");
}

#[test]
fn instances_come_and_go_between_frames() {
    // video_0's hat (index 5) is seen in frames 0 and 1 only; the object under the floor never,
    // so metadata.json does not list it.
    let dir = fixtures().join("kubric");
    let scenes = RenderedScenes::open(&dir, "object", DEFAULT_FAR).unwrap();
    let assets = |k: u64| -> Vec<String> {
        let frame = scenes.frame(k, 0).unwrap().frame;
        let mut ids: Vec<String> =
            frame.instances.iter().map(|i| i.attributes["asset_id"].as_str().unwrap().to_string()).collect();
        ids.sort();
        ids
    };
    assert!(assets(0).contains(&"Sun_hat".to_string()) && assets(1).contains(&"Sun_hat".to_string()));
    assert!(!assets(2).contains(&"Sun_hat".to_string()), "{:?}", assets(2));
    let metadata = json(&dir.join("video_0/metadata.json"));
    assert!(metadata["instances"].as_array().unwrap().iter().all(|i| i["asset_id"] != "Buried_box"));
    // video_1's kb.Cube has no asset_id: its category is --category, and it carries none.
    let scenes = RenderedScenes::open(&dir.join("video_1"), "thing", DEFAULT_FAR).unwrap();
    let names: Vec<String> = scenes.categories().iter().map(|c| c.name.clone()).collect();
    assert_eq!(names, ["cube", "thing"]);
    let frame = scenes.frame(0, 0).unwrap().frame;
    assert!(frame.instances.iter().any(|i| !i.attributes.contains_key("asset_id")));
}

#[test]
fn a_sequence_folder_alone_is_its_frames() {
    let scenes = RenderedScenes::open(&fixtures().join("kubric/video_1"), "object", DEFAULT_FAR).unwrap();
    let names: Vec<&str> = (0..scenes.available().unwrap()).map(|k| scenes.scene(k).name.unwrap()).collect();
    assert_eq!(names, ["video_1/00000", "video_1/00001"]);
}

#[test]
fn a_stopped_run_is_read_as_far_as_it_is_written() {
    let dir = fixtures().join("kubric-stopped");
    let scenes = RenderedScenes::open(&dir, "object", DEFAULT_FAR).unwrap();
    let names: Vec<&str> = (0..scenes.available().unwrap()).map(|k| scenes.scene(k).name.unwrap()).collect();
    assert_eq!(names, ["video_1/00000", "video_1/00001"]);
    assert!(dir.join("video_2/segmentation_00001.png").is_file());
    let notes = scenes.notes().join("\n");
    assert!(notes.contains("video_2 skipped: metadata.json is not written"), "{notes}");
    let alone = refusal(&dir.join("video_2"), "stopped", When::Listed);
    assert!(alone.contains("video_2: metadata.json missing; Kubric writes it after every frame's images"), "{alone}");
}

/// A copy of the fixture's sequences in a fresh folder, with `categories` as its categories.json.
fn with_categories(name: &str, categories: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("vkdiff-kubric-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    for sequence in ["video_0", "video_1"] {
        let (from, to) = (fixtures().join("kubric").join(sequence), dir.join(sequence));
        std::fs::create_dir_all(&to).unwrap();
        for entry in std::fs::read_dir(&from).unwrap() {
            let path = entry.unwrap().path();
            std::fs::copy(&path, to.join(path.file_name().unwrap())).unwrap();
        }
    }
    std::fs::write(dir.join("categories.json"), categories).unwrap();
    dir
}

#[test]
fn categories_json_beside_the_sequences_gives_the_ids_and_must_name_every_category() {
    let names = ["Bag", "Hat", "Shoe", "Toys", "cube", "object"];
    let listed: Vec<Value> = names
        .iter()
        .enumerate()
        .map(|(k, n)| serde_json::json!({"id": 10 + k, "name": n, "supercategory": "thing"}))
        .collect();
    let named = with_categories("named", &serde_json::json!({ "categories": listed }).to_string());
    let scenes = RenderedScenes::open(&named, "object", DEFAULT_FAR).unwrap();
    let got: Vec<(u32, String)> = scenes.categories().iter().map(|c| (c.id, c.name.clone())).collect();
    assert_eq!(got, names.iter().enumerate().map(|(k, n)| (10 + k as u32, n.to_string())).collect::<Vec<_>>());
    let frame = scenes.frame(0, 0).unwrap().frame;
    assert!(frame.instances.iter().all(|i| i.category_id >= 10));
    std::fs::remove_dir_all(&named).unwrap();

    let short = with_categories("short", &serde_json::json!({"categories": [{"id": 1, "name": "Toys"}]}).to_string());
    let e = RenderedScenes::open(&short, "object", DEFAULT_FAR).unwrap_err().to_string();
    assert!(e.contains("categories.json: names no category `Bag`") && !e.contains('\n'), "{e}");
    std::fs::remove_dir_all(&short).unwrap();
}

#[test]
fn broken_frames_are_refused_in_one_line_naming_the_file() {
    let bad = fixtures().join("kubric-bad");
    for (fault, when, needle) in [
        (
            "missing-tiff",
            When::Listed,
            "scene missing-tiff/00001: depth_00001.tiff: missing (metadata.json says the frame is there)",
        ),
        (
            "wrong-size",
            When::Listed,
            "scene wrong-size/00000: segmentation_00000.png: 47×40, metadata.json's resolution is 48×40",
        ),
        ("bad-metadata", When::Listed, "bad-metadata: metadata.json: not Kubric's metadata: EOF while parsing"),
        (
            "unknown-index",
            When::Read,
            "scene unknown-index/00000: segmentation_00000.png: pixel (5, 30) is index 3; metadata.json lists 2 instances",
        ),
        (
            "frame-count",
            When::Listed,
            "frame-count: metadata.json: camera.positions has 1 frames, metadata.num_frames says 2",
        ),
        (
            "float-depth",
            When::Listed,
            "scene float-depth/00000: depth_00000.tiff: Gray(16) unsigned, not the one-channel float32 depth Kubric writes",
        ),
        ("mixed", When::Listed, "holds BlenderProc .hdf5 files and Kubric sequences; one layout per folder"),
    ] {
        let refused = refusal(&bad.join(fault), fault, when);
        assert!(refused.contains(needle), "{fault}: {refused}");
    }
}
