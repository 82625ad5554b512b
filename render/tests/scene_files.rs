//! The files of a scene folder, read back through independent readers: COCO against
//! instances.png, depth.exr against the rendered frame, camera.json, control.png, and crops
//! against the full frame.

mod common;

use std::path::Path;

use serde_json::Value;
use vkdiff_render::output::{write_scene, OutputOptions};
use vkdiff_render::rle::Rle;
use vkdiff_render::scene::{Scene, SceneConfig};

const SEED: u64 = 21;

/// One scene with three 512² crops, written once for all tests of this file.
fn scene_dir() -> &'static Path {
    static DIR: std::sync::OnceLock<std::path::PathBuf> = std::sync::OnceLock::new();
    DIR.get_or_init(|| {
        let dir = common::scratch("scene-files").join("scene");
        let options = OutputOptions { crops: 3, crop_size: 512, ..OutputOptions::default() };
        write_scene(&dir, SEED, &SceneConfig::default(), &options).unwrap();
        dir
    })
}

/// Checks annotations.json against instances.png in `dir`; returns the annotations.
fn check_coco(dir: &Path) -> Vec<Value> {
    let coco = common::read_json(&dir.join("annotations.json"));
    let (w, h, ids) = common::read_ids(&dir.join("instances.png"));
    assert_eq!(coco["images"][0]["width"], w);
    assert_eq!(coco["images"][0]["height"], h);
    assert_eq!(coco["categories"], serde_json::json!([{"id": 1, "name": "mushroom", "supercategory": "mushroom"}]));
    let annotations = coco["annotations"].as_array().unwrap().clone();
    let k = annotations.len();
    assert_eq!(ids.iter().copied().max().unwrap() as usize, k, "ids in instances.png run to K");
    let mut pixels = vec![0u64; k + 1];
    let mut boxes = vec![(u32::MAX, u32::MAX, 0u32, 0u32); k + 1];
    for (i, &id) in ids.iter().enumerate() {
        let (x, y) = ((i % w as usize) as u32, (i / w as usize) as u32);
        pixels[id as usize] += 1;
        let b = &mut boxes[id as usize];
        *b = (b.0.min(x), b.1.min(y), b.2.max(x), b.3.max(y));
    }
    for (n, ann) in annotations.iter().enumerate() {
        let id = n + 1;
        assert_eq!(ann["id"], id, "annotation ids run 1..K");
        assert_eq!(
            (ann["image_id"].as_u64(), ann["category_id"].as_u64(), ann["iscrowd"].as_u64()),
            (Some(1), Some(1), Some(0))
        );
        assert!(pixels[id] > 0, "instance {id} has pixels");
        assert_eq!(ann["area"].as_u64().unwrap(), pixels[id], "area of {id} is its pixel count");
        let b = boxes[id];
        assert_eq!(ann["bbox"], serde_json::json!([b.0, b.1, b.2 - b.0 + 1, b.3 - b.1 + 1]), "bbox of {id}");
        assert_eq!(ann["segmentation"]["size"], serde_json::json!([h, w]));
        let rle = Rle::from_coco_string(ann["segmentation"]["counts"].as_str().unwrap(), h, w).unwrap();
        let mask = rle.to_mask();
        assert!(mask.iter().zip(&ids).all(|(&m, &i)| m == (i as usize == id)), "mask of {id} is instances.png == {id}");
        let age = ann["age"].as_f64().unwrap();
        assert!((0.05..=1.0).contains(&age));
        assert!((ann["cap_diameter_mm"].as_f64().unwrap() - 30.0 * age).abs() < 1e-9);
        assert_eq!(ann["position_m"].as_array().unwrap().len(), 3);
    }
    annotations
}

#[test]
fn coco_areas_boxes_and_masks_equal_instances_png() {
    let annotations = check_coco(scene_dir());
    assert!(annotations.len() > 100, "{} instances", annotations.len());
}

#[test]
fn depth_exr_holds_the_rendered_depth_in_metres() {
    let (w, h, name, depth) = common::read_exr(&std::fs::read(scene_dir().join("depth.exr")).unwrap());
    assert_eq!((w, h, name.as_str()), (1920, 1080, "Z"));
    let frame = Scene::build(SEED, &SceneConfig::default()).unwrap().render();
    assert!(depth.iter().zip(&frame.depth).all(|(a, b)| a.to_bits() == b.to_bits()));
    // The ground lies about 1 m below the camera, mushrooms up to a few cm above it.
    assert!(depth.iter().all(|&z| z > 0.95 && z < 1.01), "depth range");
}

#[test]
fn camera_json_and_control_png_follow_the_frame() {
    let camera = common::read_json(&scene_dir().join("camera.json"));
    let fx = camera["K"][0][0].as_f64().unwrap();
    assert!((fx - 50.0 / 36.0 * 1920.0).abs() < 1e-9);
    assert_eq!(camera["K"][0][2], 959.5);
    assert_eq!(camera["T_world_camera_opencv"]["matrix"][2], serde_json::json!([0.0, 0.0, -1.0, 1.0]));
    let (w, h, color, bits, rgb) = common::read_png(&scene_dir().join("control.png"));
    assert_eq!((w, h, color, bits), (1920, 1080, png::ColorType::Rgb, png::BitDepth::Eight));
    assert!(rgb.chunks(3).all(|p| p[0] == p[1] && p[1] == p[2]), "grey in three channels");
    let frame = Scene::build(SEED, &SceneConfig::default()).unwrap().render();
    let nearest = (0..frame.depth.len()).min_by(|&a, &b| frame.depth[a].total_cmp(&frame.depth[b])).unwrap();
    let farthest = (0..frame.depth.len()).max_by(|&a, &b| frame.depth[a].total_cmp(&frame.depth[b])).unwrap();
    assert_eq!((rgb[nearest * 3], rgb[farthest * 3]), (255, 0), "near is bright, per-image range");
    let (_, _, color, _, _) = common::read_png(&scene_dir().join("preview.png"));
    assert_eq!(color, png::ColorType::Rgb);
}

#[test]
fn crops_are_windows_of_the_full_frame() {
    let full = scene_dir();
    let full_annotations = check_coco(full);
    let (fw, _, full_ids) = common::read_ids(&full.join("instances.png"));
    let (_, _, _, full_depth) = common::read_exr(&std::fs::read(full.join("depth.exr")).unwrap());
    let full_camera = common::read_json(&full.join("camera.json"));
    let full_area = |id: u16| full_annotations[id as usize - 1]["area"].as_u64().unwrap();
    for k in 0..3 {
        let dir = full.join(format!("crops/{k}"));
        let crop_annotations = check_coco(&dir);
        let camera = common::read_json(&dir.join("camera.json"));
        let (x0, y0) = (
            camera["crop_offset_px"][0].as_u64().unwrap() as usize,
            camera["crop_offset_px"][1].as_u64().unwrap() as usize,
        );
        assert!(x0 + 512 <= 1920 && y0 + 512 <= 1080, "crop {k} inside the frame");
        for (row, shift) in [(0, x0), (1, y0)] {
            let expected = full_camera["K"][row][2].as_f64().unwrap() - shift as f64;
            assert_eq!(camera["K"][row][2].as_f64().unwrap(), expected, "crop {k} principal point");
        }
        let (w, h, ids) = common::read_ids(&dir.join("instances.png"));
        let (_, _, _, depth) = common::read_exr(&std::fs::read(dir.join("depth.exr")).unwrap());
        assert_eq!((w, h), (512, 512));
        let mut crop_pixels_of_full = std::collections::HashMap::<u16, u64>::new();
        for y in 0..512 {
            for x in 0..512 {
                let (i, j) = (y * 512 + x, (y + y0) * fw as usize + x + x0);
                assert_eq!(depth[i].to_bits(), full_depth[j].to_bits(), "crop {k} depth at ({x},{y})");
                let (crop_id, full_id) = (ids[i], full_ids[j]);
                *crop_pixels_of_full.entry(full_id).or_default() += 1;
                if crop_id > 0 {
                    let crop_bed = &crop_annotations[crop_id as usize - 1]["bed_index"];
                    assert_eq!(
                        crop_bed,
                        &full_annotations[full_id as usize - 1]["bed_index"],
                        "crop {k} pixel ({x},{y}) is the same mushroom"
                    );
                }
            }
        }
        // Kept instances hold at least a tenth of their full-frame pixels; dropped ones less.
        let kept: std::collections::HashSet<u64> =
            crop_annotations.iter().map(|a| a["bed_index"].as_u64().unwrap()).collect();
        for (&full_id, &count) in crop_pixels_of_full.iter().filter(|(&id, _)| id > 0) {
            let bed = full_annotations[full_id as usize - 1]["bed_index"].as_u64().unwrap();
            assert_eq!(
                kept.contains(&bed),
                count as f64 >= 0.1 * full_area(full_id) as f64,
                "crop {k}, full id {full_id}"
            );
        }
    }
}
