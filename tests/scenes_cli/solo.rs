//! Unity Perception's SOLO sequences (tests/fixtures/scenes/solo): every annotation one colour
//! of the instance segmentation, with the steps' 3D boxes and cameras.

use super::*;

/// A SOLO scene (`sequence.K/stepM`, or `sequence.K/stepM.<sensor>`) as its files give it: each
/// colour its InstanceSegmentationAnnotation lists is the instance `instanceId`, of category
/// `labelId`; black, of either alpha, 0.
fn solo_scene(dir: &Path, scene: &str) -> SourceScene {
    let (sequence, step) = scene.split_once('/').unwrap();
    let (step, sensor) = step.split_once('.').map_or((step, None), |(s, c)| (s, Some(c)));
    let folder = dir.join(sequence);
    let data = read_json(&folder.join(format!("{step}.frame_data.json")));
    let segmentation = |c: &Value| -> Option<Value> {
        let of = |a: &&Value| a["@type"] == "type.unity.com/unity.solo.InstanceSegmentationAnnotation";
        c["annotations"].as_array().unwrap().iter().find(of).cloned()
    };
    let capture = data["captures"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| segmentation(c).is_some() && sensor.is_none_or(|s| c["id"] == s))
        .unwrap();
    let annotation = segmentation(capture).unwrap();
    let file = std::fs::File::open(folder.join(annotation["filename"].as_str().unwrap())).unwrap();
    let mut reader = png::Decoder::new(std::io::BufReader::new(file)).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgba, "Unity's instance images are RGBA");
    let (mut id_of, mut category) = (BTreeMap::new(), BTreeMap::new());
    for i in annotation["instances"].as_array().unwrap() {
        let colour: Vec<u8> = i["color"].as_array().unwrap().iter().map(|c| c.as_u64().unwrap() as u8).collect();
        let id = i["instanceId"].as_u64().unwrap() as u32;
        id_of.insert(colour, id);
        category.insert(id, i["labelId"].as_u64().unwrap());
    }
    let ids = buf[..info.buffer_size()]
        .chunks(4)
        .map(|c| match id_of.get(c) {
            Some(&id) => id,
            None if c == [0, 0, 0, 255] || c == [0, 0, 0, 0] => 0,
            None => panic!("{scene}: colour {c:?} not listed"),
        })
        .collect();
    SourceScene { width: info.width as usize, ids, category }
}

#[test]
fn solo_steps_make_a_set_whose_masks_are_the_colour_maps() {
    let RenderedFixture { scenes: dataset, checked, coco, .. } = render_fixture("solo", solo_scene);
    let images = coco["images"].as_array().unwrap();
    let named: Vec<&str> = images.iter().map(|i| i["scene"].as_str().unwrap()).collect();
    let want = [
        "sequence.0/step0",
        "sequence.0/step1",
        "sequence.1/step0.camera",
        "sequence.1/step0.camera2",
        "sequence.1/step1",
    ];
    assert_eq!(named, want, "each capture, in sequence and step order");
    // Each image: the camera, fx and fy from the capture's matrix (P00 first, P11 fifth) and its
    // dimension, and a pose; each annotation Unity's instanceId, its label, and its 3D box.
    for image in images {
        let scene = image["scene"].as_str().unwrap();
        let (sequence, step) = scene.split_once('/').unwrap();
        let (step, sensor) = step.split_once('.').map_or((step, "camera"), |(s, c)| (s, c));
        let data = read_json(&dataset.join(sequence).join(format!("{step}.frame_data.json")));
        let capture = data["captures"].as_array().unwrap().iter().find(|c| c["id"] == sensor).unwrap();
        let m = |i: usize| capture["matrix"][i].as_f64().unwrap();
        let [w, h] = [0, 1].map(|i| capture["dimension"][i].as_f64().unwrap());
        let k = |r: usize, c: usize| image["camera"]["K"][r][c].as_f64().unwrap();
        assert!((k(0, 0) - m(0) * w / 2.0).abs() < 1e-9 && (k(1, 1) - m(4) * h / 2.0).abs() < 1e-9, "{scene}");
        assert!(!image["camera"]["T_world_camera_opencv"].is_null(), "{scene}: the capture's pose");
        for a in coco["annotations"].as_array().unwrap().iter().filter(|a| a["image_id"] == image["id"]) {
            let instance = solo_scene(&dataset, scene).category;
            let id = a["instance_id"].as_u64().unwrap() as u32;
            assert_eq!(a["category_id"].as_u64(), instance.get(&id).copied(), "{scene}: instance {id}");
            assert!(a["label_name"].is_string() && a["pose"]["R"].is_array() && a["bbox_3d"]["min"].is_array(), "{a}");
            assert_eq!(a["keypoints"].as_array().unwrap().len(), 27, "{scene}: the box's nine keypoints");
        }
    }
    assert!(checked >= 15, "{checked} annotations");
    let categories: Vec<(u64, &str)> = coco["categories"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| (c["id"].as_u64().unwrap(), c["name"].as_str().unwrap()))
        .collect();
    assert_eq!(categories, [(1, "Crate"), (3, "Box")], "labelIds and labelNames as Unity wrote them");
    // A run stopped mid-step: the steps written, the cut one skipped with a note.
    let stopped = scratch("scenes-solo-stopped").join("set");
    let note = run_ok(&[
        "dataset",
        "--render-only",
        "--scenes",
        scenes("solo-stopped").to_str().unwrap(),
        "--out",
        stopped.to_str().unwrap(),
    ]);
    assert!(note.contains("note: sequence.1/step1 skipped: step1.frame_data.json is not written yet"), "{note}");
    assert_eq!(read_json(&stopped.join("annotations.json"))["images"].as_array().unwrap().len(), 4);
}
