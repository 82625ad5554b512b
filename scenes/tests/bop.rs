//! BOP scenes (tests/fixtures/scenes/bop, written by BlenderProc's own write_bop through
//! tools/make_bop_fixtures.py) read as BOP defines them, each held to the fixture's own files read here with the
//! png crate: every image of scene_camera.json one scene in scene then image order, each
//! instance exactly its visible mask's pixels with its obj_id and pose, depth in metres with 0 as
//! background, the camera's K that of cam_K; broken scenes refused naming the file.

mod common;

use common::{fixtures, json, refusal, When};
use std::collections::BTreeMap;
use std::path::Path;
use vkdiff_render::camera::Pose;
use vkdiff_render::geometry::{Box3, Keypoint, ObjectPose, BOX_KEYPOINTS};
use vkdiff_scenes::{RenderedScenes, SceneSource, DEFAULT_FAR};

/// A grey PNG's samples (8 or 16 bits) and width.
fn grey(path: &Path) -> (Vec<u32>, usize) {
    let file = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let mut reader = png::Decoder::new(file).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let bytes = &buf[..info.buffer_size()];
    let values = match info.bit_depth {
        png::BitDepth::Sixteen => bytes.chunks(2).map(|b| u16::from_be_bytes([b[0], b[1]]) as u32).collect(),
        _ => bytes.iter().map(|&v| v as u32).collect(),
    };
    (values, info.width as usize)
}

/// Image ids of a scene's scene_camera.json, as numbers, ascending.
fn image_ids(scene: &Path) -> Vec<u64> {
    let mut ids: Vec<u64> =
        json(&scene.join("scene_camera.json")).as_object().unwrap().keys().map(|k| k.parse().unwrap()).collect();
    ids.sort_unstable();
    ids
}

#[test]
fn every_image_is_a_scene_with_its_masks_depth_camera_and_poses() {
    let split = fixtures().join("bop");
    let scenes = RenderedScenes::open(&split, "object", DEFAULT_FAR).unwrap();
    let scene_dirs = ["000000", "000001"].map(|s| split.join(s));
    let mut names = Vec::new();
    for dir in &scene_dirs {
        for im in image_ids(dir) {
            names.push(format!("{}/{im:06}", dir.file_name().unwrap().to_string_lossy()));
        }
    }
    let listed: Vec<&str> = (0..scenes.available().unwrap()).map(|k| scenes.scene(k).name.unwrap()).collect();
    assert_eq!(listed, names, "scene then image order, image ids as numbers");
    let (mut instances, mut dropped, mut sky, mut occluded) = (0, 0, 0, 0);
    for (k, name) in names.iter().enumerate() {
        let (scene, im) = name.split_once('/').unwrap();
        let (dir, im_id) = (split.join(scene), im.parse::<u64>().unwrap());
        let camera = &json(&dir.join("scene_camera.json"))[im_id.to_string()];
        let gts = json(&dir.join("scene_gt.json"))[im_id.to_string()].as_array().unwrap().clone();
        let frame = scenes.frame(k as u64, 0).unwrap().frame;
        let (width, height) = (frame.width as usize, frame.height as usize);
        assert_eq!((width, height), (scenes.scene(k as u64).width as usize, scenes.scene(k as u64).height as usize));
        // Depth: value × depth_scale mm, in metres; 0 is background.
        let (depth, w) = grey(&dir.join(format!("depth/{im}.png")));
        assert_eq!(w, width);
        let scale = camera["depth_scale"].as_f64().unwrap();
        for (p, &v) in depth.iter().enumerate() {
            let z = frame.depth[p];
            if v == 0 {
                assert!(z == f32::INFINITY, "{name}: pixel {p} has no depth");
                sky += 1;
            } else {
                assert_eq!(z, (v as f64 * scale / 1000.0) as f32, "{name}: pixel {p}");
            }
        }
        // Instances: the gts whose visible mask is not empty, in gt order, each exactly its mask.
        let mut shown = Vec::new();
        for (gt_id, gt) in gts.iter().enumerate() {
            let (mask, _) = grey(&dir.join(format!("mask_visib/{im}_{gt_id:06}.png")));
            if mask.iter().all(|&v| v == 0) {
                dropped += 1;
                continue;
            }
            shown.push((gt_id, gt, mask));
        }
        assert_eq!(frame.instances.len(), shown.len(), "{name}");
        for (n, (gt_id, gt, mask)) in shown.iter().enumerate() {
            let id = n as u16 + 1;
            for (p, &v) in mask.iter().enumerate() {
                assert_eq!(frame.ids[p] == id, v != 0, "{name}: gt {gt_id} at pixel {p}");
            }
            let instance = &frame.instances[n];
            assert_eq!(instance.category_id as u64, gt["obj_id"].as_u64().unwrap());
            let a = &instance.attributes;
            assert_eq!((&a["obj_id"], a["gt_id"].as_u64()), (&gt["obj_id"], Some(*gt_id as u64)));
            // The pose: cam_R_m2c as 3×3, cam_t_m2c in metres.
            let pose = ObjectPose::of(a).expect("every gt has its pose");
            let given = |key: &str| gt[key].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect::<Vec<_>>();
            assert_eq!(pose.r.concat(), given("cam_R_m2c"), "{name}: R");
            assert_eq!(pose.t.to_vec(), given("cam_t_m2c").iter().map(|mm| mm / 1000.0).collect::<Vec<_>>());
            // The amodal mask: exactly mask/'s pixels.
            let (whole, _) = grey(&dir.join(format!("mask/{im}_{gt_id:06}.png")));
            let amodal = instance.amodal.as_ref().expect("the scene has mask/").to_image(width as u32, height as u32);
            assert_eq!(amodal, whole.iter().map(|&v| v != 0).collect::<Vec<_>>(), "{name}: gt {gt_id} amodal");
            occluded += whole.iter().zip(mask).filter(|(&w, &v)| w != 0 && v == 0).count();
            instances += 1;
        }
        // The camera: K as cam_K; the world pose where scene_camera.json gives it.
        let c = frame.camera.as_ref().expect("BOP images have their camera");
        let k: Vec<f64> = camera["cam_K"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        assert_eq!([c.fx, c.cx, c.fy, c.cy], [k[0], k[2], k[4], k[5]], "{name}: K");
        match (&c.pose, camera.get("cam_R_w2c")) {
            (Pose::Given(m), Some(r)) => {
                let r: Vec<f64> = r.as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
                let t: Vec<f64> = camera["cam_t_w2c"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
                // T_world_camera · (world → camera) is the identity: to 1e-5 for R, which write_bop
                // gives in Blender's single precision (RᵀR is I to 9e-7 in the fixture).
                for (i, row) in m.iter().take(3).enumerate() {
                    for j in 0..3 {
                        let product: f64 = (0..3).map(|l| row[l] * r[3 * l + j]).sum();
                        assert!((product - (i == j) as u8 as f64).abs() < 1e-5, "{name}: R");
                    }
                    let origin: f64 = (0..3).map(|l| row[l] * t[l] / 1000.0).sum::<f64>() + row[3];
                    assert!(origin.abs() < 1e-9, "{name}: t");
                }
            }
            (Pose::Unknown, None) => {}
            (pose, given) => panic!("{name}: {pose:?} for {given:?}"),
        }
    }
    assert!(instances >= 10 && dropped >= 1 && sky > 0, "{instances} instances, {dropped} hidden, {sky} sky pixels");
    assert!(occluded > 0, "the amodal masks cover hidden pixels");
}

#[test]
fn categories_are_obj_ids_named_by_categories_json_else_by_id() {
    let split = fixtures().join("bop");
    let named: BTreeMap<u64, String> = json(&split.join("categories.json"))["categories"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| (c["id"].as_u64().unwrap(), c["name"].as_str().unwrap().to_string()))
        .collect();
    let mut obj_ids: Vec<u64> = ["000000", "000001"]
        .iter()
        .flat_map(|s| {
            json(&split.join(s).join("scene_gt.json")).as_object().unwrap().values().cloned().collect::<Vec<_>>()
        })
        .flat_map(|gts| gts.as_array().unwrap().iter().map(|g| g["obj_id"].as_u64().unwrap()).collect::<Vec<_>>())
        .collect();
    obj_ids.sort_unstable();
    obj_ids.dedup();
    let name = |id: u64, names: &BTreeMap<u64, String>| names.get(&id).cloned().unwrap_or(format!("obj_{id:06}"));
    let categories = RenderedScenes::open(&split, "object", DEFAULT_FAR).unwrap().categories();
    let got: Vec<(u64, String)> = categories.iter().map(|c| (c.id as u64, c.name.clone())).collect();
    let want: Vec<(u64, String)> = obj_ids.iter().map(|&id| (id, name(id, &named))).collect();
    assert_eq!(got, want);
    assert!(got.iter().any(|(_, n)| n.starts_with("obj_")) && got.iter().any(|(_, n)| !n.starts_with("obj_")));
    // One scene folder given alone: no categories.json beside it, every name by id.
    let alone = RenderedScenes::open(&split.join("000001"), "object", DEFAULT_FAR).unwrap();
    assert_eq!(alone.scene(0).name, Some("000001/000002"));
    assert!(alone.categories().iter().all(|c| c.name == format!("obj_{:06}", c.id)), "{:?}", alone.categories());
}

#[test]
fn broken_scenes_are_refused_naming_the_file() {
    let bad = fixtures().join("bop-bad");
    for (fault, when, needle) in [
        ("missing-mask", When::Listed, "scene 000000/000001: mask_visib/000001_000002.png: missing"),
        ("depth-size", When::Listed, "scene 000000/000001: rgb/000001.png: 96×72, its depth/ image is 95×72"),
        ("overlap", When::Read, "scene 000000/000000: mask_visib/000000_000001.png: pixel"),
    ] {
        let refused = refusal(&bad.join(fault), fault, when);
        assert!(refused.contains(needle), "{fault}: {refused}");
    }
}

#[test]
fn models_boxes_give_each_gt_its_bbox_3d_and_projected_keypoints() {
    let root = fixtures().join("bop-dataset");
    let expected = json(&root.join("expected_keypoints.json"));
    let info = json(&root.join("models/models_info.json"));
    for given in [root.join("train_pbr"), root.join("train_pbr/000000")] {
        let scenes = RenderedScenes::open(&given, "object", DEFAULT_FAR).unwrap();
        for category in scenes.categories() {
            assert_eq!(category.keypoints, BOX_KEYPOINTS.map(String::from), "{}", category.name);
            assert_eq!(category.skeleton.len(), 12);
        }
        let (mut seen, mut hidden, mut absent) = (0, 0, 0);
        for k in 0..scenes.available().unwrap() {
            let im = scenes.scene(k).name.unwrap().split_once('/').unwrap().1.parse::<u64>().unwrap();
            let gts = expected["000000"][im.to_string()].as_array().unwrap();
            let frame = scenes.frame(k, 0).unwrap().frame;
            for instance in &frame.instances {
                let a = &instance.attributes;
                let gt = &gts[a["gt_id"].as_u64().unwrap() as usize];
                let model = &info[a["obj_id"].to_string()];
                let mm = |key: &str| model[key].as_f64().unwrap();
                let bbox = Box3::of(a).expect("a model's box");
                for (i, axis) in ["x", "y", "z"].iter().enumerate() {
                    let (lo, size) = (mm(&format!("min_{axis}")), mm(&format!("size_{axis}")));
                    assert_eq!((bbox.min[i], bbox.max[i]), (lo / 1000.0, (lo + size) / 1000.0));
                }
                let want: Vec<Keypoint> = gt
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|p| Keypoint {
                        x: p[0].as_f64().unwrap(),
                        y: p[1].as_f64().unwrap(),
                        v: p[2].as_u64().unwrap() as u8,
                    })
                    .collect();
                // numpy's to 1/100 pixel, as annotations.json writes them.
                for (got, want) in instance.keypoints.iter().zip(&want) {
                    let close = (got.x - want.x).abs() <= 0.005 + 1e-9 && (got.y - want.y).abs() <= 0.005 + 1e-9;
                    assert!(close && got.v == want.v, "image {im}, {a:?}: {got:?}, numpy {want:?}");
                }
                assert_eq!(instance.keypoints.len(), 9);
                for p in &want {
                    match p.v {
                        2 => seen += 1,
                        1 => hidden += 1,
                        _ => absent += 1,
                    }
                }
            }
        }
        assert!(seen > 0 && hidden > 0 && absent > 0, "{seen} seen, {hidden} hidden, {absent} outside");
    }
    // Without models_info.json: no box, no keypoints.
    let plain = RenderedScenes::open(&fixtures().join("bop"), "object", DEFAULT_FAR).unwrap();
    assert!(plain.categories().iter().all(|c| c.keypoints.is_empty()));
    assert!(plain
        .frame(0, 0)
        .unwrap()
        .frame
        .instances
        .iter()
        .all(|i| i.keypoints.is_empty() && Box3::of(&i.attributes).is_none()));
}
