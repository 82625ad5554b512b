//! Omniverse Replicator's BasicWriter frames (tests/fixtures/scenes/replicator): every annotation
//! one colour of the instance map, with the frame's 3D boxes and camera.

use super::*;

/// Every class of a Replicator folder's semantics mappings (BACKGROUND and UNLABELLED aside),
/// sorted: the categories' names, ids 1 + index.
fn replicator_classes(dir: &Path) -> Vec<String> {
    let mut classes = BTreeSet::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let name = entry.unwrap().file_name().to_string_lossy().into_owned();
        if name.starts_with("instance_segmentation_semantics_mapping_") {
            for v in read_json(&dir.join(&name)).as_object().unwrap().values() {
                classes.insert(v["class"].as_str().unwrap().to_string());
            }
        }
    }
    classes.into_iter().filter(|c| c != "BACKGROUND" && c != "UNLABELLED").collect()
}

/// A Replicator frame as its files give it: each colour of instance_segmentation_N.png an
/// instance (its index in the mapping's keys + 1), of the category of its class; BACKGROUND and
/// UNLABELLED 0.
fn replicator_scene(dir: &Path, frame: &str) -> SourceScene {
    let file = std::fs::File::open(dir.join(format!("instance_segmentation_{frame}.png"))).unwrap();
    let mut reader = png::Decoder::new(std::io::BufReader::new(file)).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgba, "BasicWriter's colourised instances are RGBA");
    let semantics = read_json(&dir.join(format!("instance_segmentation_semantics_mapping_{frame}.json")));
    let classes = replicator_classes(dir);
    let (mut id_of, mut category) = (BTreeMap::new(), BTreeMap::new());
    for (k, (key, v)) in semantics.as_object().unwrap().iter().enumerate() {
        let class = v["class"].as_str().unwrap();
        let id = match classes.iter().position(|c| c == class) {
            Some(index) => {
                category.insert(k as u32 + 1, index as u64 + 1);
                k as u32 + 1
            }
            None => 0,
        };
        id_of.insert(key.clone(), id);
    }
    let ids = buf[..info.buffer_size()]
        .chunks(4)
        .map(|c| id_of[&format!("({}, {}, {}, {})", c[0], c[1], c[2], c[3])])
        .collect();
    SourceScene { width: info.width as usize, ids, category }
}

/// The same JSON but for numbers, which may differ by 1e-9.
fn same_numbers(a: &Value, b: &Value) -> bool {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => (x.as_f64().unwrap() - y.as_f64().unwrap()).abs() < 1e-9,
        (Value::Array(x), Value::Array(y)) => x.len() == y.len() && x.iter().zip(y).all(|(x, y)| same_numbers(x, y)),
        (Value::Object(x), Value::Object(y)) => {
            x.len() == y.len() && x.iter().all(|(k, v)| y.get(k).is_some_and(|w| same_numbers(v, w)))
        }
        _ => a == b,
    }
}

#[test]
fn replicator_frames_make_a_set_whose_masks_are_the_colour_maps() {
    let RenderedFixture { scenes: frames, checked, coco, note } = render_fixture("replicator", replicator_scene);
    // The whole frames, in order; the last one, without its semantics mapping, skipped with a note.
    let mut whole: Vec<String> = std::fs::read_dir(&frames)
        .unwrap()
        .filter_map(|e| {
            let name = e.unwrap().file_name().to_string_lossy().into_owned();
            Some(name.strip_prefix("instance_segmentation_semantics_mapping_")?.strip_suffix(".json")?.to_string())
        })
        .collect();
    whole.sort();
    let images = coco["images"].as_array().unwrap();
    let named: Vec<&str> = images.iter().map(|i| i["scene"].as_str().unwrap()).collect();
    assert_eq!(named, whole);
    let skipped = format!("{:04}", whole.len());
    assert!(frames.join(format!("rgb_{skipped}.png")).is_file());
    assert!(note.contains(&format!("note: frame {skipped} skipped")), "{note}");
    // Each annotation carries its colour's prim path, and its 3D box row's bbox_3d, pose and
    // projected corners as numpy computed them (the corners shifted into the image's window, those
    // outside it 0, 0, 0); each image the camera where camera_params is given.
    let expected = read_json(&fixtures().join("scenes/replicator-expected.json"));
    let mut boxed = 0;
    for image in images {
        let frame = image["scene"].as_str().unwrap();
        let prims = read_json(&frames.join(format!("instance_segmentation_mapping_{frame}.json")));
        let paths: BTreeSet<&str> = prims.as_object().unwrap().values().map(|v| v.as_str().unwrap()).collect();
        for a in coco["annotations"].as_array().unwrap().iter().filter(|a| a["image_id"] == image["id"]) {
            let prim = a["prim_path"].as_str().unwrap();
            assert!(paths.contains(prim), "{frame}: {prim}");
            let want = &expected[frame][prim];
            assert_eq!(a.get("bbox_3d").is_some(), !want.is_null(), "{frame} {prim}");
            if want.is_null() {
                assert!(
                    a["keypoints"].as_array().unwrap().iter().all(|v| v == 0),
                    "{frame} {prim}: no row, no corners"
                );
                continue;
            }
            let pose = a.get("pose").unwrap_or(&Value::Null);
            assert!(
                same_numbers(&a["bbox_3d"], &want["bbox_3d"]) && same_numbers(pose, &want["pose"]),
                "{frame} {prim}"
            );
            let [ox, oy] = [0, 1].map(|i| image["crop"]["offset_px"][i].as_f64().unwrap());
            let [w, h] = ["width", "height"].map(|k| image[k].as_f64().unwrap());
            let written = a["keypoints"].as_array().unwrap();
            for (k, p) in want["keypoints"].as_array().unwrap().iter().enumerate() {
                let (x, y) = (p[0].as_f64().unwrap() - ox, p[1].as_f64().unwrap() - oy);
                let inside = p[2] != 0 && (-0.5..w - 0.5).contains(&x) && (-0.5..h - 0.5).contains(&y);
                let got = &written[3 * k..3 * k + 3];
                let (gx, gy) = (got[0].as_f64().unwrap(), got[1].as_f64().unwrap());
                let same = if inside {
                    got[2] == p[2] && (gx - x).abs() < 0.005 + 1e-9 && (gy - y).abs() < 0.005 + 1e-9
                } else {
                    got == [0, 0, 0]
                };
                assert!(same, "{frame} {prim} keypoint {k}: {got:?}, numpy {p} less the offset");
            }
            boxed += 1;
        }
        let params = frames.join(format!("camera_params_{frame}.json"));
        assert_eq!(image["camera"].is_null(), !params.is_file(), "{frame}");
        if params.is_file() {
            // Focal lengths in pixels: the projection's NDC scales × half the render's size.
            let params = read_json(&params);
            let [w, h] = [0, 1].map(|i| params["renderProductResolution"][i].as_f64().unwrap());
            let p = |i: usize| params["cameraProjection"][i].as_f64().unwrap();
            let k = |r: usize, c: usize| image["camera"]["K"][r][c].as_f64().unwrap();
            assert!((k(0, 0) - p(0) * w / 2.0).abs() < 1e-9 && (k(1, 1) - p(5) * h / 2.0).abs() < 1e-9, "{frame}");
            assert!(!image["camera"]["T_world_camera_opencv"].is_null(), "{frame}: the view transform's pose");
        }
    }
    assert!(checked >= 6 && boxed >= 6, "{checked} annotations, {boxed} with a box");
    let names: Vec<&str> = coco["categories"].as_array().unwrap().iter().map(|c| c["name"].as_str().unwrap()).collect();
    let ids: Vec<u64> = coco["categories"].as_array().unwrap().iter().map(|c| c["id"].as_u64().unwrap()).collect();
    let classes = replicator_classes(&frames);
    assert_eq!(names, classes.iter().map(String::as_str).collect::<Vec<_>>(), "the classes, sorted");
    assert_eq!(ids, (1..=classes.len() as u64).collect::<Vec<_>>());
}
