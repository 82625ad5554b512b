//! Kubric's sequence folders (tests/fixtures/scenes/kubric): every annotation one segmentation
//! index, of its instance's category.

use super::*;

/// A Kubric frame (`<seq>/<NNNNN>`) as its files give it: segmentation index k (the palette PNG's
/// stored index) is metadata.json's instances[k − 1], of the category its `category` (else
/// `asset_id`, else `object`) names, ids in name order over both sequences; 0 background.
fn kubric_scene(dir: &Path, scene: &str) -> SourceScene {
    let (sequence, frame) = scene.split_once('/').unwrap();
    let mut names = BTreeSet::new();
    for seq in ["video_0", "video_1"] {
        for i in read_json(&dir.join(seq).join("metadata.json"))["instances"].as_array().unwrap() {
            names.insert(i["category"].as_str().or(i["asset_id"].as_str()).unwrap_or("object").to_string());
        }
    }
    let id_of: BTreeMap<String, u64> = names.into_iter().enumerate().map(|(k, n)| (n, k as u64 + 1)).collect();
    let metadata = read_json(&dir.join(sequence).join("metadata.json"));
    let category = metadata["instances"]
        .as_array()
        .unwrap()
        .iter()
        .enumerate()
        .map(|(k, i)| {
            let name = i["category"].as_str().or(i["asset_id"].as_str()).unwrap_or("object");
            (k as u32 + 1, id_of[name])
        })
        .collect();
    let file = std::fs::File::open(dir.join(sequence).join(format!("segmentation_{frame}.png"))).unwrap();
    let mut decoder = png::Decoder::new(std::io::BufReader::new(file));
    decoder.set_transformations(png::Transformations::IDENTITY);
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Indexed, "Kubric's segmentation is a palette PNG");
    let ids = buf[..info.buffer_size()].iter().map(|&v| v as u32).collect();
    SourceScene { width: info.width as usize, ids, category }
}

#[test]
fn kubric_frames_make_a_set_whose_masks_are_the_segmentation_indices() {
    let RenderedFixture { scenes: sequences, checked, coco, .. } = render_fixture("kubric", kubric_scene);
    let images = coco["images"].as_array().unwrap();
    let named: Vec<&str> = images.iter().map(|i| i["scene"].as_str().unwrap()).collect();
    assert_eq!(named, ["video_0/00000", "video_0/00001", "video_0/00002", "video_1/00000", "video_1/00001"]);
    // Each image: the camera, fx from K (normalised: f/sw) times the width, and a pose; each
    // annotation its segmentation index, asset id where it has one, and its 3D box's keypoints.
    for image in images {
        let scene = image["scene"].as_str().unwrap();
        let (sequence, _) = scene.split_once('/').unwrap();
        let metadata = read_json(&sequences.join(sequence).join("metadata.json"));
        let k = |r: usize, c: usize| image["camera"]["K"][r][c].as_f64().unwrap();
        let kubric =
            metadata["camera"]["K"][0][0].as_f64().unwrap() * metadata["metadata"]["resolution"][0].as_f64().unwrap();
        assert!((k(0, 0) - kubric).abs() < 1e-9, "{scene}: {} vs {kubric}", k(0, 0));
        assert!(!image["camera"]["T_world_camera_opencv"].is_null(), "{scene}: the frame's pose");
        for a in coco["annotations"].as_array().unwrap().iter().filter(|a| a["image_id"] == image["id"]) {
            let index = a["instance_id"].as_u64().unwrap() as usize;
            let source = &metadata["instances"][index - 1];
            assert_eq!(a.get("asset_id"), source.get("asset_id"), "{scene}: instance {index}");
            assert!(a["pose"]["R"].is_array() && a["bbox_3d"]["min"].is_array(), "{a}");
            assert_eq!(a["keypoints"].as_array().unwrap().len(), 27, "{scene}: the box's nine keypoints");
        }
    }
    assert!(checked >= 15, "{checked} annotations");
    let categories: Vec<&str> =
        coco["categories"].as_array().unwrap().iter().map(|c| c["name"].as_str().unwrap()).collect();
    assert_eq!(categories, ["Bag", "Hat", "Shoe", "Toys", "cube", "object"], "names in order, ids 1…");
    // A run stopped before a sequence's metadata.json: that sequence skipped with a note.
    let stopped = scratch("scenes-kubric-stopped").join("set");
    let note = run_ok(&[
        "dataset",
        "--render-only",
        "--scenes",
        scenes("kubric-stopped").to_str().unwrap(),
        "--out",
        stopped.to_str().unwrap(),
    ]);
    assert!(note.contains("note: video_2 skipped: metadata.json is not written"), "{note}");
    assert_eq!(read_json(&stopped.join("annotations.json"))["images"].as_array().unwrap().len(), 2);
}
