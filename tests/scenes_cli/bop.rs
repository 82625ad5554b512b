//! BOP splits (tests/fixtures/scenes/bop): every annotation the visible mask of one object.

use super::*;

/// A BOP image (`<scene>/<im>` of the split at `split`) as its files give it: gt g's visible
/// mask (mask_visib/, non-zero inside) as instance g + 1, of category obj_id.
fn bop_scene(split: &Path, name: &str) -> SourceScene {
    let (scene, im) = name.split_once('/').unwrap();
    let dir = split.join(scene);
    let gts = read_json(&dir.join("scene_gt.json"))[im.parse::<u64>().unwrap().to_string()].clone();
    let (mut ids, mut width, mut category) = (Vec::new(), 0, BTreeMap::new());
    for (gt_id, gt) in gts.as_array().unwrap().iter().enumerate() {
        let file = std::fs::File::open(dir.join(format!("mask_visib/{im}_{gt_id:06}.png"))).unwrap();
        let mut reader = png::Decoder::new(std::io::BufReader::new(file)).read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!(info.bit_depth, png::BitDepth::Eight, "BOP's masks are 8-bit");
        width = info.width as usize;
        ids.resize(buf[..info.buffer_size()].len(), 0);
        for (p, &v) in buf[..info.buffer_size()].iter().enumerate() {
            if v != 0 {
                assert_eq!(ids[p], 0, "{name}: visible masks overlap at pixel {p}");
                ids[p] = gt_id as u32 + 1;
            }
        }
        category.insert(gt_id as u32 + 1, gt["obj_id"].as_u64().unwrap());
    }
    SourceScene { width, ids, category }
}

#[test]
fn bop_scenes_make_a_set_whose_masks_are_the_visible_masks() {
    let RenderedFixture { scenes: split, checked, coco, .. } = render_fixture("bop", bop_scene);
    let images = coco["images"].as_array().unwrap();
    // Every image of every scene_camera.json, each annotation carrying its gt's obj_id and pose.
    let mut listed = 0;
    let mut visible = 0;
    for image in images {
        let (scene, im) = image["scene"].as_str().unwrap().split_once('/').unwrap();
        let key = im.parse::<u64>().unwrap().to_string();
        let camera = &read_json(&split.join(scene).join("scene_camera.json"))[&key];
        let k = &camera["cam_K"];
        assert_eq!(
            image["camera"]["K"],
            serde_json::json!([[k[0], k[1], k[2]], [k[3], k[4], k[5]], [k[6], k[7], k[8]]])
        );
        assert_eq!(image["camera"]["T_world_camera_opencv"].is_null(), camera.get("cam_R_w2c").is_none());
        let gts = read_json(&split.join(scene).join("scene_gt.json"))[&key].clone();
        let ours: Vec<&Value> =
            coco["annotations"].as_array().unwrap().iter().filter(|a| a["image_id"] == image["id"]).collect();
        for a in &ours {
            let gt = &gts[a["gt_id"].as_u64().unwrap() as usize];
            assert_eq!((&a["obj_id"], &a["category_id"]), (&gt["obj_id"], &gt["obj_id"]));
            let r: Vec<Value> =
                a["pose"]["R"].as_array().unwrap().iter().flat_map(|row| row.as_array().unwrap().clone()).collect();
            assert_eq!(Value::from(r), gt["cam_R_m2c"]);
            let t: Vec<f64> =
                gt["cam_t_m2c"].as_array().unwrap().iter().map(|mm| mm.as_f64().unwrap() / 1000.0).collect();
            assert_eq!(a["pose"]["t"], serde_json::json!(t));
            assert!(a["amodal_area"].as_u64().unwrap() >= a["area"].as_u64().unwrap(), "the whole covers what shows");
        }
        visible += bop_scene(&split, image["scene"].as_str().unwrap()).category.len();
        listed += 1;
    }
    let in_json: usize = ["000000", "000001"]
        .iter()
        .map(|s| read_json(&split.join(s).join("scene_camera.json")).as_object().unwrap().len())
        .sum();
    assert_eq!(listed, in_json, "one image per entry of scene_camera.json");
    assert!(checked > 0 && checked < visible, "{checked} annotations of {visible} gts: the hidden one dropped");
    let names: Vec<&str> = coco["categories"].as_array().unwrap().iter().map(|c| c["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["duck", "obj_000002"], "categories.json's name, else the obj_id's");
}
