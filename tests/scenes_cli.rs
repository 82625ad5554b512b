//! `vkdiff dataset --scenes`: scenes rendered elsewhere (tests/fixtures/scenes, drawn by
//! tools/make_scene_fixtures.py: scene folders as a renderer of one's own writes them, and
//! BlenderProc's .hdf5 frames as its writer writes them, with h5py) made into sets whose every
//! annotation is the scene's instance-map pixels of one instance inside its crop, with the
//! scene's category; through --render-only and through the tiny SDXL + ControlNet; exported with
//! the categories' names; `vkdiff scene`'s own folders fed back (refusals: scenes_refusal_cli.rs).

#[path = "scenes_cli/bop.rs"]
mod bop;
mod cli;
#[path = "scenes_cli/kubric.rs"]
mod kubric;
#[path = "scenes_cli/replicator.rs"]
mod replicator;
#[path = "scenes_cli/solo.rs"]
mod solo;

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

/// A set made with `--render-only` from the `format` fixture, each mask held to what `scene`
/// (the fixture's folder, an image's name) reads from the format's own files.
struct RenderedFixture {
    /// The fixture's folder.
    scenes: PathBuf,
    /// How many annotations the masks were checked against.
    checked: usize,
    /// The set's annotations.json.
    coco: Value,
    /// What the run printed.
    note: String,
}

fn render_fixture(format: &str, scene: fn(&Path, &str) -> SourceScene) -> RenderedFixture {
    let dir = scratch(&format!("scenes-{format}")).join("set");
    let scenes = scenes(format);
    let note =
        run_ok(&["dataset", "--render-only", "--scenes", scenes.to_str().unwrap(), "--out", dir.to_str().unwrap()]);
    let checked = assert_masks_are_the_scenes(&dir, &|name| scene(&scenes, name));
    let coco = read_json(&dir.join("annotations.json"));
    RenderedFixture { scenes, checked, coco, note }
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
