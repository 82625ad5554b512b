//! Geometric labels through `vkdiff dataset --scenes`: a scene folder written by `vkdiff scene`,
//! given keypoints.json and keypoint names in categories.json, cut into crops. Each crop's
//! keypoints are the scene's shifted by the crop's offset, those outside it written as COCO
//! writes an unlabelled one (0, 0, 0); each crop's camera projects a mushroom's stem base (its
//! world position, from the annotations) to the pixel the full frame's camera.json projects it
//! to, less the offset.

mod cli;

use cli::{command, layer_pngs, rgba, scratch};
use serde_json::{json, Value};
use std::path::Path;
use vkdiff_render::rle::Rle;

fn run_ok(args: &[&str]) {
    let out = command().args(args).output().unwrap();
    assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
}

fn read_json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn write_json(path: &Path, value: &Value) {
    std::fs::write(path, serde_json::to_string_pretty(value).unwrap()).unwrap();
}

/// (u, v) of world point `p` seen by `camera` (an image entry's camera or camera.json): K and
/// T_world_camera_opencv (camera → world) inverted.
fn project(camera: &Value, p: [f64; 3]) -> (f64, f64) {
    let t = |i: usize, j: usize| camera["T_world_camera_opencv"][i][j].as_f64().unwrap();
    let d: Vec<f64> = (0..3).map(|i| p[i] - t(i, 3)).collect();
    // Camera coordinates: Rᵀ (p − c).
    let c: Vec<f64> = (0..3).map(|j| (0..3).map(|i| t(i, j) * d[i]).sum()).collect();
    let k = |i: usize, j: usize| camera["K"][i][j].as_f64().unwrap();
    (k(0, 0) * c[0] / c[2] + k(0, 2), k(1, 1) * c[1] / c[2] + k(1, 2))
}

#[test]
fn keypoints_and_cameras_follow_each_crop() {
    let root = scratch("geometry-crops");
    let scenes = root.join("scenes");
    run_ok(&[
        "scene",
        "--seed",
        "5",
        "--width",
        "320",
        "--height",
        "240",
        "--out",
        scenes.join("bed").to_str().unwrap(),
    ]);
    let bed = scenes.join("bed");
    // Three named keypoints for the mushroom category; per instance: its box's top-left corner
    // (seen), 40 pixels left of it (hidden, or unlabelled where that leaves the frame) and one
    // unlabelled point.
    let mut categories = read_json(&bed.join("categories.json"));
    categories["categories"][0]["keypoints"] = json!(["cap_left", "shadow", "unlabelled"]);
    categories["categories"][0]["skeleton"] = json!([[1, 2]]);
    write_json(&bed.join("categories.json"), &categories);
    let full = read_json(&bed.join("annotations.json"));
    let mut keypoints = serde_json::Map::new();
    for a in full["annotations"].as_array().unwrap() {
        let (x, y) = (a["bbox"][0].as_f64().unwrap() + 0.25, a["bbox"][1].as_f64().unwrap() + 0.5);
        let shadow = if x >= 40.0 { json!([x - 40.0, y, 1]) } else { json!([0, 0, 0]) };
        let flat = [json!([x, y, 2]), shadow, json!([0, 0, 0])].concat_values();
        keypoints.insert(a["id"].to_string(), flat);
    }
    write_json(&bed.join("keypoints.json"), &Value::Object(keypoints.clone()));
    let set = root.join("set");
    let cut = ["--render-only", "--seed", "2", "--crops", "3", "--crop-size", "96"];
    run_ok(&[&["dataset", "--scenes", scenes.to_str().unwrap(), "--out", set.to_str().unwrap()][..], &cut].concat());

    let coco = read_json(&set.join("annotations.json"));
    assert_eq!(coco["categories"][0]["keypoints"], categories["categories"][0]["keypoints"]);
    assert_eq!(coco["categories"][0]["skeleton"], json!([[1, 2]]));
    let frame_camera = read_json(&bed.join("camera.json"));
    let frame_camera =
        json!({"K": frame_camera["K"], "T_world_camera_opencv": frame_camera["T_world_camera_opencv"]["matrix"]});
    let (ids, width) = grey16(&bed.join("instances.png"));
    let (mut inside, mut outside, mut projected) = (0, 0, 0);
    for image in coco["images"].as_array().unwrap() {
        let offset = &image["crop"]["offset_px"];
        let (x0, y0) = (offset[0].as_f64().unwrap(), offset[1].as_f64().unwrap());
        let camera = &image["camera"];
        assert_eq!((&camera["width"], &camera["height"]), (&json!(96), &json!(96)));
        for a in coco["annotations"].as_array().unwrap().iter().filter(|a| a["image_id"] == image["id"]) {
            // The scene's instance: the one under the annotation's first pixel.
            let counts = a["segmentation"]["counts"].as_str().unwrap();
            let first = Rle::from_coco_string(counts, 96, 96).unwrap().to_mask().iter().position(|&m| m).unwrap();
            let (x, y) = (first % 96 + x0 as usize, first / 96 + y0 as usize);
            let id = ids[y * width + x] as u64;
            let source = full["annotations"].as_array().unwrap().iter().find(|s| s["id"] == id).unwrap();
            let given = keypoints[&source["id"].to_string()].as_array().unwrap();
            let got = a["keypoints"].as_array().unwrap();
            let mut labelled = 0;
            for (g, w) in got.chunks(3).zip(given.chunks(3)) {
                let (x, y, v) = (w[0].as_f64().unwrap() - x0, w[1].as_f64().unwrap() - y0, w[2].as_u64().unwrap());
                let within = (-0.5..95.5).contains(&x) && (-0.5..95.5).contains(&y);
                let want = if v > 0 && within { json!([x, y, v]) } else { json!([0, 0, 0]) };
                assert_eq!(Value::from(g.to_vec()), want, "{a}");
                if v > 0 {
                    if within {
                        inside += 1;
                        labelled += 1;
                    } else {
                        outside += 1;
                    }
                }
            }
            assert_eq!(a["num_keypoints"], labelled);
            // The stem base projects where the full frame puts it, less the offset.
            let base: Vec<f64> = source["position_m"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
            let (u, v) = project(&frame_camera, [base[0], base[1], base[2]]);
            let (cu, cv) = project(camera, [base[0], base[1], base[2]]);
            assert!((u - x0 - cu).abs() < 1e-6 && (v - y0 - cv).abs() < 1e-6, "({u}, {v}) − offset vs ({cu}, {cv})");
            projected += 1;
        }
    }
    assert!(inside > 10 && outside > 0 && projected > 10, "{inside} inside, {outside} cut off, {projected} projected");
}

/// A 16-bit grey PNG's values and width.
fn grey16(path: &Path) -> (Vec<u16>, usize) {
    let mut reader =
        png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap())).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.bit_depth, png::BitDepth::Sixteen);
    (buf[..info.buffer_size()].chunks(2).map(|b| u16::from_be_bytes([b[0], b[1]])).collect(), info.width as usize)
}

/// Lists of values, joined.
trait ConcatValues {
    fn concat_values(self) -> Value;
}

impl<const N: usize> ConcatValues for [Value; N] {
    fn concat_values(self) -> Value {
        Value::from(self.iter().flat_map(|v| v.as_array().unwrap().clone()).collect::<Vec<_>>())
    }
}

fn stdout_of(args: &[&str]) -> String {
    let out = command().args(args).output().unwrap();
    assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn preview_draws_keypoints_and_amodal_outlines_and_stats_count_them() {
    let root = scratch("geometry-look");
    let set = root.join("set");
    let split = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/scenes/bop-dataset/train_pbr");
    run_ok(&["dataset", "--render-only", "--scenes", split.to_str().unwrap(), "--out", set.to_str().unwrap()]);
    let coco = read_json(&set.join("annotations.json"));
    let annotations = coco["annotations"].as_array().unwrap();

    let stats: Value =
        serde_json::from_str(&stdout_of(&["dataset", "stats", set.to_str().unwrap(), "--json"])).unwrap();
    let g = &stats["geometry"];
    let vs: Vec<u64> = annotations
        .iter()
        .flat_map(|a| a["keypoints"].as_array().unwrap().iter().skip(2).step_by(3))
        .map(|v| v.as_u64().unwrap())
        .collect();
    let count = |v: u64| vs.iter().filter(|&&x| x == v).count();
    assert_eq!(
        g["keypoints"],
        json!({"instances": annotations.len(), "seen": count(2), "hidden": count(1), "not_in_image": count(0)})
    );
    let occluded = annotations.iter().filter(|a| a["area"].as_u64() < a["amodal_area"].as_u64()).count();
    assert!(occluded > 0);
    assert_eq!((&g["amodal"]["instances"], &g["amodal"]["occluded"]), (&json!(annotations.len()), &json!(occluded)));
    assert_eq!((&g["poses"], &g["boxes_3d"]), (&json!(annotations.len()), &json!(annotations.len())));
    assert_eq!(g["images_with_camera"], coco["images"].as_array().unwrap().len());

    let html = root.join("preview.html");
    stdout_of(&["dataset", "preview", set.to_str().unwrap(), "--out", html.to_str().unwrap(), "--count", "2"]);
    let page = std::fs::read_to_string(&html).unwrap();
    assert!(page.contains("value=\"keypoints\"") && page.contains("value=\"amodal\""), "the overlays' switches");
    let images = coco["images"].as_array().unwrap();
    let (keypoint_layers, amodal_layers) = (layer_pngs(&page, "keypoints"), layer_pngs(&page, "amodal"));
    assert_eq!((keypoint_layers.len(), amodal_layers.len()), (2, 2));
    for (image, (points, outlines)) in images.iter().zip(keypoint_layers.iter().zip(&amodal_layers)) {
        let (w, points) = rgba(points);
        let (_, outlines) = rgba(outlines);
        for a in annotations.iter().filter(|a| a["image_id"] == image["id"]) {
            // A marker at every labelled keypoint: its centre drawn, filled (seen) or not (hidden).
            for p in a["keypoints"].as_array().unwrap().chunks(3) {
                let (x, y, v) = (
                    p[0].as_f64().unwrap().round() as usize,
                    p[1].as_f64().unwrap().round() as usize,
                    p[2].as_u64().unwrap(),
                );
                if v > 0 && x + 2 < w && y + 2 < points.len() / w && x >= 2 && y >= 2 {
                    assert_eq!(points[(y + 2) * w + x][3], 255, "{a}: the marker's ring at ({x}, {y})");
                }
            }
        }
        let union: Vec<bool> = annotations
            .iter()
            .filter(|a| a["image_id"] == image["id"])
            .map(|a| {
                Rle::from_coco_string(
                    a["amodal_segmentation"]["counts"].as_str().unwrap(),
                    image["height"].as_u64().unwrap() as u32,
                    w as u32,
                )
                .unwrap()
                .to_mask()
            })
            .fold(vec![false; outlines.len()], |u, m| u.iter().zip(m).map(|(a, b)| *a || b).collect());
        let drawn: Vec<usize> = (0..outlines.len()).filter(|&p| outlines[p][3] != 0).collect();
        assert!(!drawn.is_empty() && drawn.iter().all(|&p| union[p]), "amodal outlines off their masks");
    }
}
