//! `vkdiff dataset --scenes`: scenes rendered elsewhere (tests/fixtures/scenes, drawn by
//! tools/make_scene_fixtures.py: scene folders as a renderer of one's own writes them, and
//! BlenderProc's .hdf5 frames as its writer writes them, with h5py) made into sets whose every
//! annotation is the scene's instance-map pixels of one instance inside its crop, with the
//! scene's category; through --render-only and through the tiny SDXL + ControlNet; exported with
//! the categories' names; `vkdiff scene`'s own folders fed back (refusals: scenes_refusal_cli.rs).

mod cli;

use cli::{command, png_pixels, scratch, tree};
use serde_json::Value;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use vkdiff_render::rle::Rle;

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures")
}

fn scenes(format: &str) -> PathBuf {
    fixtures().join("scenes").join(format)
}

fn run_ok(args: &[&str]) -> String {
    let out = command().args(args).output().unwrap();
    let text = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{args:?}: {text}");
    text
}

fn read_json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// A scene's instance map (the renderer's ids, as written) and each id's category.
struct SourceScene {
    width: usize,
    ids: Vec<u32>,
    category: BTreeMap<u32, u64>,
}

fn folder_scene(dir: &Path) -> SourceScene {
    let mut reader =
        png::Decoder::new(std::io::BufReader::new(std::fs::File::open(dir.join("instances.png")).unwrap()))
            .read_info()
            .unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let ids: Vec<u32> = match info.bit_depth {
        png::BitDepth::Sixteen => {
            buf[..info.buffer_size()].chunks(2).map(|b| u16::from_be_bytes([b[0], b[1]]) as u32).collect()
        }
        _ => buf[..info.buffer_size()].iter().map(|&v| v as u32).collect(),
    };
    let categories = read_json(&dir.join("categories.json"));
    let category = categories["instances"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(k, v)| (k.parse().unwrap(), v.as_u64().unwrap()))
        .collect();
    SourceScene { width: info.width as usize, ids, category }
}

fn blenderproc_scene(file: &Path) -> SourceScene {
    let f = hdf5_reader::Hdf5File::open(file).unwrap();
    let segmap = f.dataset("/instance_segmaps").unwrap();
    let width = segmap.shape()[1] as usize;
    let ids: Vec<u32> =
        segmap.read_raw_bytes().unwrap().chunks(4).map(|b| i32::from_le_bytes(b.try_into().unwrap()) as u32).collect();
    let attributes: Value =
        serde_json::from_str(&f.dataset("/instance_attribute_maps").unwrap().read_string().unwrap()).unwrap();
    let category = attributes
        .as_array()
        .unwrap()
        .iter()
        .map(|a| (a["idx"].as_u64().unwrap() as u32, a["category_id"].as_u64().unwrap()))
        .collect();
    SourceScene { width, ids, category }
}

/// Every image of the set at `set` against its scene: each annotation is exactly the pixels of
/// one instance of the scene's map inside the image's window, of that instance's category; and
/// every instance with at least a tenth of its pixels inside (the default --crop-min-fraction)
/// and a category other than 0 (BlenderProc's background) has its annotation. Returns the
/// annotations checked.
fn assert_masks_are_the_scenes(set: &Path, source: &dyn Fn(&str) -> SourceScene) -> usize {
    let coco = read_json(&set.join("annotations.json"));
    let mut by_image: BTreeMap<u64, Vec<&Value>> = BTreeMap::new();
    for a in coco["annotations"].as_array().unwrap() {
        by_image.entry(a["image_id"].as_u64().unwrap()).or_default().push(a);
    }
    let mut checked = 0;
    for image in coco["images"].as_array().unwrap() {
        let scene = source(image["scene"].as_str().expect("images of rendered scenes name their scene"));
        let [x0, y0] = [0, 1].map(|i| image["crop"]["offset_px"][i].as_u64().unwrap() as usize);
        let [w, h] = [0, 1].map(|i| image["crop"]["size_px"][i].as_u64().unwrap() as usize);
        let at = |x: usize, y: usize| scene.ids[(y0 + y) * scene.width + x0 + x];
        let mut annotated = BTreeSet::new();
        for a in by_image.remove(&image["id"].as_u64().unwrap()).unwrap_or_default() {
            let s = &a["segmentation"];
            let mask = Rle::from_coco_string(s["counts"].as_str().unwrap(), h as u32, w as u32).unwrap().to_mask();
            let first = mask.iter().position(|&m| m).expect("no empty annotation");
            let raw = at(first % w, first / w);
            for (p, &m) in mask.iter().enumerate() {
                assert_eq!(
                    m,
                    at(p % w, p / w) == raw,
                    "image {}: annotation {} against instance {raw}",
                    image["id"],
                    a["id"]
                );
            }
            assert_eq!(a["category_id"].as_u64(), scene.category.get(&raw).copied(), "instance {raw}'s category");
            assert!(annotated.insert(raw), "instance {raw} annotated twice");
            checked += 1;
        }
        let count = |inside: bool| {
            let mut n: BTreeMap<u32, usize> = BTreeMap::new();
            for (p, &id) in scene.ids.iter().enumerate() {
                let (x, y) = (p % scene.width, p / scene.width);
                if !inside || (x0..x0 + w).contains(&x) && (y0..y0 + h).contains(&y) {
                    *n.entry(id).or_default() += 1;
                }
            }
            n
        };
        let (frame, crop) = (count(false), count(true));
        let wanted: BTreeSet<u32> = crop
            .iter()
            .filter(|(&id, &n)| id != 0 && scene.category.get(&id) != Some(&0) && n as f64 >= 0.1 * frame[&id] as f64)
            .map(|(&id, _)| id)
            .collect();
        assert_eq!(annotated, wanted, "image {}: the instances annotated", image["id"]);
    }
    checked
}

#[test]
fn scene_folders_make_a_set_whose_masks_are_the_instance_maps() {
    let dir = scratch("scenes-folders").join("set");
    let scenes_dir = scenes("folders");
    let render = |out: &Path| {
        let cut = ["--crops", "3", "--crop-size", "64", "--seed", "5"];
        let set =
            ["dataset", "--render-only", "--scenes", scenes_dir.to_str().unwrap(), "--out", out.to_str().unwrap()];
        run_ok(&[&set[..], &cut].concat());
    };
    render(&dir);
    let checked = assert_masks_are_the_scenes(&dir, &|name| folder_scene(&scenes_dir.join(name)));
    assert!(checked > 40, "{checked} annotations");
    let coco = read_json(&dir.join("annotations.json"));
    let expected = read_json(&fixtures().join("scenes/expected.json"));
    assert_eq!(coco["categories"], expected["categories"], "the scenes' categories, ids and names kept");
    assert_eq!(coco["images"].as_array().unwrap().len(), 9);
    // Images cut from the frames at the edge hold instances the edge cuts.
    let cut = coco["annotations"].as_array().unwrap().iter().filter(|a| {
        let b = &a["bbox"];
        b[0] == 0 || b[1] == 0 || b[0].as_u64().unwrap() + b[2].as_u64().unwrap() == 64
    });
    assert!(cut.count() > 5);
    // The same seed and settings give the same bytes.
    let again = scratch("scenes-folders-again").join("set");
    render(&again);
    assert!(tree(&dir) == tree(&again));
}

#[test]
fn the_same_scenes_through_the_tiny_sdxl_and_controlnet() {
    let root = scratch("scenes-diffusion");
    let scenes_dir = scenes("folders");
    let (rendered, diffused) = (root.join("rendered"), root.join("diffused"));
    let common = ["--scenes", scenes_dir.to_str().unwrap(), "--crops", "2", "--crop-size", "64", "--seed", "9"];
    let out = |d: &Path| ["--out".to_string(), d.display().to_string()];
    let args = |extra: &[&str], d: &Path| -> Vec<String> {
        ["dataset"]
            .iter()
            .map(|s| s.to_string())
            .chain(common.iter().map(|s| s.to_string()))
            .chain(out(d))
            .chain(extra.iter().map(|s| s.to_string()))
            .collect()
    };
    run_ok(&strs(&args(&["--render-only"], &rendered)));
    let model = fixtures().join("pipeline/tiny-sdxl");
    let controlnet = fixtures().join("workflow/controlnet");
    let diffusion = [
        "--model",
        model.to_str().unwrap(),
        "--controlnet",
        controlnet.to_str().unwrap(),
        "--steps",
        "2",
        "--prompt",
        "an orchard",
        "--init-strength",
        "0.6",
    ];
    run_ok(&strs(&args(&diffusion, &diffused)));
    let records = |d: &Path| -> Vec<Value> {
        (0..6).map(|i| read_json(&d.join(format!("records/{i:06}.json")))["annotations"].clone()).collect()
    };
    assert_eq!(records(&rendered), records(&diffused), "the same annotations whatever makes the images");
    assert_masks_are_the_scenes(&diffused, &|name| folder_scene(&scenes_dir.join(name)));
    let coco = read_json(&diffused.join("annotations.json"));
    for image in coco["images"].as_array().unwrap() {
        let own = (image["scene"] == "orchard-a").then_some("ripe red apples among green leaves on a branch");
        assert_eq!(image["prompt"].as_str(), Some(own.unwrap_or("an orchard")), "{image}");
    }
    // img2img starts from the renderer's own image where the scene has one (orchard-a's shaded.png).
    let init = png_pixels(&diffused.join("init/000000.png"));
    let shaded = png_pixels(&scenes_dir.join("orchard-a/shaded.png"));
    let entry = &coco["images"][0];
    let [x0, y0] = [0, 1].map(|i| entry["crop"]["offset_px"][i].as_u64().unwrap() as usize);
    assert_eq!(&init[..3], &shaded[(y0 * 160 + x0) * 3..][..3], "the first pixel of the crop of shaded.png");
}

#[test]
fn blenderproc_files_make_a_set_with_their_categories_and_names() {
    let dir = scratch("scenes-blenderproc").join("set");
    let scenes_dir = scenes("blenderproc");
    run_ok(&["dataset", "--render-only", "--scenes", scenes_dir.to_str().unwrap(), "--out", dir.to_str().unwrap()]);
    let checked = assert_masks_are_the_scenes(&dir, &|name| blenderproc_scene(&scenes_dir.join(name)));
    let expected = read_json(&fixtures().join("scenes/expected.json"));
    let instances: usize =
        expected["blenderproc"].as_object().unwrap().values().map(|s| s["instances"].as_object().unwrap().len()).sum();
    assert_eq!(checked, instances, "every instance, the ground plane (category 0) left out");
    let coco = read_json(&dir.join("annotations.json"));
    assert_eq!(coco["categories"], expected["categories"], "names from categories.json beside the files");
    assert!(coco["annotations"]
        .as_array()
        .unwrap()
        .iter()
        .all(|a| a["name"].as_str().is_some_and(|n| n.contains('.'))));
    // Whole frames of 144×112, the far value (1e10) background.
    assert_eq!((coco["images"][0]["width"].as_u64(), coco["images"][0]["height"].as_u64()), (Some(144), Some(112)));
    // Without categories.json the categories are named by their ids.
    let bare = scratch("scenes-blenderproc-bare");
    std::fs::create_dir_all(&bare).unwrap();
    std::fs::copy(scenes_dir.join("0.hdf5"), bare.join("0.hdf5")).unwrap();
    let set = bare.join("set");
    run_ok(&["dataset", "--render-only", "--scenes", bare.to_str().unwrap(), "--out", set.to_str().unwrap()]);
    let names: Vec<String> = read_json(&set.join("annotations.json"))["categories"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["name"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(names, ["category_1", "category_2", "category_3"]);
}

#[test]
fn exports_carry_the_categories_names() {
    let root = scratch("scenes-exports");
    let (dir, scenes_dir) = (root.join("set"), scenes("folders"));
    run_ok(&[
        "dataset",
        "--render-only",
        "--scenes",
        scenes_dir.to_str().unwrap(),
        "--out",
        dir.to_str().unwrap(),
        "--crops",
        "2",
        "--crop-size",
        "64",
    ]);
    let yolo = root.join("yolo");
    run_ok(&["dataset", "export", dir.to_str().unwrap(), "--format", "yolo", "--out", yolo.to_str().unwrap()]);
    let yaml = std::fs::read_to_string(yolo.join("data.yaml")).unwrap();
    assert!(yaml.contains("names:\n  0: \"apple\"\n  1: \"leaf\"\n  2: \"branch\"\n"), "{yaml}");
    let hf = root.join("hf");
    run_ok(&["dataset", "export", dir.to_str().unwrap(), "--format", "hf", "--out", hf.to_str().unwrap()]);
    let card = std::fs::read_to_string(hf.join("README.md")).unwrap();
    assert!(
        card.contains("'0': \"apple\"") && card.contains("'1': \"leaf\"") && card.contains("'2': \"branch\""),
        "{card}"
    );
    let metadata = std::fs::read_to_string(hf.join("train/metadata.jsonl")).unwrap();
    let row: Value = serde_json::from_str(metadata.lines().next().unwrap()).unwrap();
    let categories = row["objects"]["category"].as_array().unwrap();
    assert!(!categories.is_empty() && categories.iter().all(|c| c.as_u64().is_some_and(|c| c < 3)), "{row}");
    let stats = run_ok(&["dataset", "stats", dir.to_str().unwrap()]);
    let out = command().args(["dataset", "stats", dir.to_str().unwrap(), "--json"]).output().unwrap();
    let stats_json: Value = serde_json::from_slice(&out.stdout).unwrap();
    let names: Vec<&str> =
        stats_json["categories"].as_array().unwrap().iter().map(|c| c["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["apple", "leaf", "branch"], "{stats}");
    let total: u64 =
        stats_json["categories"].as_array().unwrap().iter().map(|c| c["instances"].as_u64().unwrap()).sum();
    assert_eq!(total, stats_json["instances"].as_u64().unwrap());
}

#[test]
fn vkdiff_scene_folders_fed_back_give_the_built_in_annotations() {
    let root = scratch("scenes-round-trip");
    let beds = root.join("beds");
    let size = ["--width", "480", "--height", "272"];
    run_ok(&[&["scene", "--seed", "3", "--count", "2", "--out", beds.to_str().unwrap()][..], &size].concat());
    let (built_in, fed_back) = (root.join("built-in"), root.join("fed-back"));
    let cut = ["--render-only", "--seed", "3", "--crops", "2", "--crop-size", "128"];
    run_ok(&[&["dataset", "--out", built_in.to_str().unwrap(), "--count", "2"][..], &cut, &size].concat());
    run_ok(&[&["dataset", "--out", fed_back.to_str().unwrap(), "--scenes", beds.to_str().unwrap()][..], &cut].concat());
    let annotations = |d: &Path| -> Vec<Value> {
        let coco = read_json(&d.join("annotations.json"));
        coco["annotations"]
            .as_array()
            .unwrap()
            .iter()
            .map(|a| {
                let keep = ["id", "image_id", "category_id", "segmentation", "area", "bbox", "iscrowd", "mask_id"];
                keep.iter().map(|k| (k.to_string(), a[*k].clone())).collect::<serde_json::Map<_, _>>().into()
            })
            .collect()
    };
    assert_eq!(annotations(&built_in), annotations(&fed_back));
    assert_eq!(
        read_json(&built_in.join("annotations.json"))["categories"],
        read_json(&fed_back.join("annotations.json"))["categories"]
    );
    for name in ["depth/000000.exr", "masks/000001.png", "control/000002.png"] {
        assert!(std::fs::read(built_in.join(name)).unwrap() == std::fs::read(fed_back.join(name)).unwrap(), "{name}");
    }
    // camera.json read back: each crop's camera is the built-in one's (K shifted by the crop).
    let cameras = |d: &Path| -> Vec<Value> {
        read_json(&d.join("annotations.json"))["images"]
            .as_array()
            .unwrap()
            .iter()
            .map(|i| i["camera"].clone())
            .collect()
    };
    let built_in_cameras = cameras(&built_in);
    assert!(built_in_cameras.iter().all(|c| c["K"].is_array() && c["width"] == 128 && c["height"] == 128));
    assert_eq!(built_in_cameras, cameras(&fed_back));
}

fn strs(v: &[String]) -> Vec<&str> {
    v.iter().map(String::as_str).collect()
}

#[test]
fn shards_a_resume_and_a_scene_without_categories_json() {
    // Two shards into one folder make the set one run makes.
    let root = scratch("scenes-shards");
    let scenes_dir = scenes("folders");
    let set = |out: &Path, extra: &[&str]| {
        let args =
            ["dataset", "--render-only", "--scenes", scenes_dir.to_str().unwrap(), "--out", out.to_str().unwrap()];
        run_ok(&[&args[..], &["--crops", "2", "--crop-size", "64"], extra].concat());
    };
    let (one, sharded) = (root.join("one"), root.join("sharded"));
    set(&one, &[]);
    set(&sharded, &["--shard", "0/2"]);
    set(&sharded, &["--shard", "1/2"]);
    assert!(tree(&one) == tree(&sharded), "two shards and one run differ");
    // A run stopped after its fourth image (its later images and the annotations never
    // written) resumes into the same set.
    let resumed = root.join("resumed");
    set(&resumed, &[]);
    std::fs::remove_file(resumed.join("annotations.json")).unwrap();
    for n in 4..6 {
        for (dir, ext) in
            [("records", "json"), ("images", "png"), ("masks", "png"), ("depth", "exr"), ("control", "png")]
        {
            std::fs::remove_file(resumed.join(dir).join(format!("{n:06}.{ext}"))).unwrap();
        }
    }
    set(&resumed, &[]);
    assert!(tree(&one) == tree(&resumed), "a resumed set differs from one run's");
    // A scene folder with no categories.json: every instance is --category, id 1.
    let bare = root.join("bare");
    std::fs::create_dir_all(bare.join("only")).unwrap();
    for file in ["depth.exr", "instances.png"] {
        std::fs::copy(scenes_dir.join("orchard-a").join(file), bare.join("only").join(file)).unwrap();
    }
    let out = root.join("trees");
    let args = ["dataset", "--render-only", "--scenes", bare.to_str().unwrap(), "--out", out.to_str().unwrap()];
    run_ok(&[&args[..], &["--category", "tree"]].concat());
    let coco = read_json(&out.join("annotations.json"));
    assert_eq!(coco["categories"], serde_json::json!([{"id": 1, "name": "tree", "supercategory": "tree"}]));
    assert!(coco["annotations"].as_array().unwrap().iter().all(|a| a["category_id"] == 1));
    let expected = read_json(&fixtures().join("scenes/expected.json"));
    assert_eq!(
        coco["annotations"].as_array().unwrap().len(),
        expected["folders"]["orchard-a"]["instances"].as_object().unwrap().len()
    );
}

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
    let dir = scratch("scenes-bop").join("set");
    let split = scenes("bop");
    run_ok(&["dataset", "--render-only", "--scenes", split.to_str().unwrap(), "--out", dir.to_str().unwrap()]);
    let checked = assert_masks_are_the_scenes(&dir, &|name| bop_scene(&split, name));
    let coco = read_json(&dir.join("annotations.json"));
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
    let dir = scratch("scenes-replicator").join("set");
    let frames = scenes("replicator");
    let note =
        run_ok(&["dataset", "--render-only", "--scenes", frames.to_str().unwrap(), "--out", dir.to_str().unwrap()]);
    let checked = assert_masks_are_the_scenes(&dir, &|frame| replicator_scene(&frames, frame));
    let coco = read_json(&dir.join("annotations.json"));
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
    let dir = scratch("scenes-solo").join("set");
    let dataset = scenes("solo");
    run_ok(&["dataset", "--render-only", "--scenes", dataset.to_str().unwrap(), "--out", dir.to_str().unwrap()]);
    let checked = assert_masks_are_the_scenes(&dir, &|scene| solo_scene(&dataset, scene));
    let coco = read_json(&dir.join("annotations.json"));
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
    let dir = scratch("scenes-kubric").join("set");
    let sequences = scenes("kubric");
    run_ok(&["dataset", "--render-only", "--scenes", sequences.to_str().unwrap(), "--out", dir.to_str().unwrap()]);
    let checked = assert_masks_are_the_scenes(&dir, &|scene| kubric_scene(&sequences, scene));
    let coco = read_json(&dir.join("annotations.json"));
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
