//! `vkdiff dataset export` as a user runs it, on render-only sets (no model needed): YOLO
//! polygons rasterised back against every mask, scene-safe splits that stay put as the set grows,
//! WebDataset shards read by GNU tar, the Hugging Face metadata, and bad input refused whole.

mod cli;

use cli::{render_set_of, scratch, tree, vkdiff};
use serde_json::Value;
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use vkdiff_render::rle::Rle;

/// A render-only set of `count` scenes of 320×256, two 128² crops each.
fn render_set(dir: &Path, count: u64) {
    render_set_of(dir, count, 320, 256, 128);
}

/// Ten scenes, twenty images, made once.
fn set() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = scratch("export-set").join("set");
        render_set(&dir, 10);
        dir
    })
}

fn export(dir: &Path, out: &Path, extra: &[&str]) -> String {
    let mut args = vec!["dataset", "export", dir.to_str().unwrap(), "--out", out.to_str().unwrap()];
    args.extend(extra);
    let result = vkdiff(&args);
    assert!(result.status.success(), "{args:?}: {}", String::from_utf8_lossy(&result.stderr));
    String::from_utf8_lossy(&result.stdout).into_owned()
}

fn read_json(path: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Pixel centres inside the polygon, even-odd: written apart from the exporter's own.
fn fill(points: &[(f64, f64)], width: usize, height: usize) -> Vec<bool> {
    let mut mask = vec![false; width * height];
    for y in 0..height {
        for x in 0..width {
            let (px, py) = (x as f64 + 0.5, y as f64 + 0.5);
            let mut inside = false;
            for (i, &(x1, y1)) in points.iter().enumerate() {
                let (x2, y2) = points[(i + 1) % points.len()];
                if (y1 > py) != (y2 > py) && px < x1 + (py - y1) / (y2 - y1) * (x2 - x1) {
                    inside = !inside;
                }
            }
            mask[y * width + x] = inside;
        }
    }
    mask
}

/// The set's COCO file: its images by file name, and its annotations by image id.
fn coco_of(dir: &Path) -> (HashMap<String, Value>, HashMap<u64, Vec<Value>>) {
    let coco = read_json(&dir.join("annotations.json"));
    let images =
        coco["images"].as_array().unwrap().iter().map(|i| (i["file_name"].as_str().unwrap().into(), i.clone()));
    let mut annotations: HashMap<u64, Vec<Value>> = HashMap::new();
    for a in coco["annotations"].as_array().unwrap() {
        annotations.entry(a["image_id"].as_u64().unwrap()).or_default().push(a.clone());
    }
    (images.collect(), annotations)
}

/// An exported instance mask (16-bit grey PNG) holds, under each annotation's `mask_id`,
/// exactly the pixels of the annotation's COCO RLE.
fn assert_mask_holds(png_bytes: &[u8], annotations: &[Value], what: &str) {
    let mut reader = png::Decoder::new(std::io::Cursor::new(png_bytes)).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let frame = reader.next_frame(&mut buf).unwrap();
    assert_eq!(frame.bit_depth, png::BitDepth::Sixteen, "{what}");
    let ids: Vec<u16> = buf[..frame.buffer_size()].chunks(2).map(|b| u16::from_be_bytes([b[0], b[1]])).collect();
    for a in annotations {
        let rle = Rle::from_coco_string(a["segmentation"]["counts"].as_str().unwrap(), frame.height, frame.width);
        let coco_mask = rle.unwrap().to_mask();
        let id = a["mask_id"].as_u64().unwrap() as u16;
        // `to_mask` is row-major, as the PNG is.
        assert_eq!(coco_mask.len(), ids.len(), "{what}");
        let differ = coco_mask.iter().zip(&ids).filter(|(&c, &m)| c != (m == id)).count();
        assert_eq!(differ, 0, "{what}: instance {id} differs from its COCO mask in {differ} pixels");
    }
}

/// At full-HD scale, where most instances are large enough for their outlines to be simplified.
#[test]
fn yolo_polygons_cover_every_instance_mask() {
    let dir = scratch("export-yolo");
    let set = dir.join("set");
    render_set_of(&set, 3, 1920, 1080, 512);
    let out = dir.join("yolo");
    let summary = export(&set, &out, &["--format", "yolo", "--val-fraction", "0.2", "--test-fraction", "0.2"]);
    assert!(summary.contains("IoU min"), "{summary}");
    let yaml = std::fs::read_to_string(out.join("data.yaml")).unwrap();
    for line in ["train: images/train", "val: images/val", "test: images/test", "  0: \"mushroom\""] {
        assert!(yaml.lines().any(|l| l == line), "data.yaml lacks {line}:\n{yaml}");
    }
    assert!(!yaml.contains("path:"), "the folder is the root wherever it moves");
    // Without a val split, Ultralytics (which needs one) validates on train.
    let no_val = dir.join("no-val");
    export(&set, &no_val, &["--format", "yolo", "--val-fraction", "0"]);
    let yaml = std::fs::read_to_string(no_val.join("data.yaml")).unwrap();
    assert!(yaml.lines().any(|l| l == "val: images/train") && !yaml.contains("test:"), "{yaml}");
    let mut ious = polygon_ious(&set, &out);
    // Whole frames, wider than tall: x and y are each normalised by their own side.
    let wide = dir.join("wide");
    let mut args = vec!["dataset", "--render-only", "--out", wide.to_str().unwrap()];
    args.extend("--seed 11 --crops 0 --count 2 --width 640 --height 360".split(' '));
    let rendered = vkdiff(&args);
    assert!(rendered.status.success(), "{}", String::from_utf8_lossy(&rendered.stderr));
    export(&wide, &dir.join("wide-yolo"), &["--format", "yolo"]);
    ious.extend(polygon_ious(&wide, &dir.join("wide-yolo")));
    // Both scenes in val (this seed): Ultralytics, which needs a train key, trains on val.
    let all_val = dir.join("all-val");
    export(&wide, &all_val, &["--format", "yolo", "--val-fraction", "0.5", "--seed", "1"]);
    let yaml = std::fs::read_to_string(all_val.join("data.yaml")).unwrap();
    assert_eq!(std::fs::read_dir(all_val.join("images/train")).map_or(0, |d| d.count()), 0, "train is not empty");
    assert!(yaml.lines().any(|l| l == "train: images/val") && yaml.lines().any(|l| l == "val: images/val"), "{yaml}");
    let min = ious.iter().copied().fold(1.0, f64::min);
    let mean = ious.iter().sum::<f64>() / ious.len() as f64;
    let points = read_labels_points(&out);
    eprintln!(
        "{} polygons ({points} points) rasterised back: IoU with their masks min {min:.3}, mean {mean:.3}",
        ious.len()
    );
    assert!(ious.len() > 100 && min >= 0.9, "{} instances, IoU min {min}", ious.len());
    assert!(mean < 1.0, "no outline was simplified: the test misses what it is for");
}

/// Each YOLO polygon of the export in `out` of `set`, normalised coordinates scaled back by the
/// image's own width and height and filled, against its instance's COCO mask: the IoUs.
fn polygon_ious(set: &Path, out: &Path) -> Vec<f64> {
    let coco = read_json(&set.join("annotations.json"));
    let mut masks: HashMap<u64, Vec<&Value>> = HashMap::new();
    for a in coco["annotations"].as_array().unwrap() {
        masks.entry(a["image_id"].as_u64().unwrap()).or_default().push(a);
    }
    let mut ious = Vec::new();
    for image in coco["images"].as_array().unwrap() {
        let stem = image["file_name"].as_str().unwrap().trim_start_matches("images/").trim_end_matches(".png");
        let (w, h) = (image["width"].as_u64().unwrap() as usize, image["height"].as_u64().unwrap() as usize);
        let labels = ["train", "val", "test"]
            .iter()
            .find_map(|s| std::fs::read_to_string(out.join(format!("labels/{s}/{stem}.txt"))).ok())
            .unwrap_or_else(|| panic!("no label file for {stem}"));
        let split = ["train", "val", "test"].into_iter().find(|s| out.join(format!("labels/{s}/{stem}.txt")).exists());
        assert!(out.join(format!("images/{}/{stem}.png", split.unwrap())).is_file());
        let want = &masks[&image["id"].as_u64().unwrap()];
        assert_eq!(labels.lines().count(), want.len(), "{stem}: a line per instance");
        for (line, a) in labels.lines().zip(want) {
            let numbers: Vec<f64> = line.split(' ').map(|v| v.parse().unwrap()).collect();
            assert_eq!(numbers[0], 0.0, "class 0, the first category");
            assert!(numbers[1..].iter().all(|v| (0.0..=1.0).contains(v)) && numbers.len() % 2 == 1);
            let points: Vec<(f64, f64)> = numbers[1..].chunks(2).map(|p| (p[0] * w as f64, p[1] * h as f64)).collect();
            let filled = fill(&points, w, h);
            let s = &a["segmentation"];
            let mask = Rle::from_coco_string(s["counts"].as_str().unwrap(), h as u32, w as u32).unwrap().to_mask();
            let both = filled.iter().zip(&mask).filter(|(a, b)| **a && **b).count();
            let either = filled.iter().zip(&mask).filter(|(a, b)| **a || **b).count();
            ious.push(both as f64 / either as f64);
        }
    }
    ious
}

/// Polygon points in every label file.
fn read_labels_points(out: &Path) -> usize {
    tree(&out.join("labels")).values().map(|text| text.split(|&b| b == b' ').count()).sum::<usize>() / 2
}

/// The split of each image of a COCO export, by file name; checks the splits share no scene.
fn coco_splits(out: &Path) -> BTreeMap<String, String> {
    let mut splits = BTreeMap::new();
    let mut scenes: HashMap<u64, String> = HashMap::new();
    for split in ["train", "val", "test"] {
        let Ok(text) = std::fs::read(out.join(format!("{split}.json"))) else { continue };
        let coco: Value = serde_json::from_slice(&text).unwrap();
        for image in coco["images"].as_array().unwrap() {
            let scene = image["scene_seed"].as_u64().unwrap();
            assert_eq!(scenes.entry(scene).or_insert(split.into()), split, "scene {scene} is in two splits");
            assert!(out.join(image["file_name"].as_str().unwrap()).is_file());
            assert!(out.join(image["mask_file"].as_str().unwrap()).is_file());
            splits.insert(image["file_name"].as_str().unwrap().to_string(), split.to_string());
        }
        let ids: Vec<u64> = coco["images"].as_array().unwrap().iter().map(|i| i["id"].as_u64().unwrap()).collect();
        assert!(coco["annotations"].as_array().unwrap().iter().all(|a| ids.contains(&a["image_id"].as_u64().unwrap())));
    }
    splits
}

#[test]
fn coco_splits_keep_scenes_together_and_stay_put_as_the_set_grows() {
    let dir = scratch("export-coco");
    let flags = ["--format", "coco", "--val-fraction", "0.3", "--test-fraction", "0.2", "--seed", "4"];
    export(set(), &dir.join("small"), &flags);
    let small = coco_splits(&dir.join("small"));
    assert_eq!(small.len(), 20, "every image in one split");
    assert!(["train", "val", "test"].iter().all(|s| small.values().any(|v| v == s)), "{small:?}");
    let annotations = |split: &str| {
        read_json(&dir.join("small").join(format!("{split}.json")))["annotations"].as_array().unwrap().len()
    };
    let all = read_json(&set().join("annotations.json"))["annotations"].as_array().unwrap().len();
    assert_eq!(annotations("train") + annotations("val") + annotations("test"), all);
    let grown = dir.join("grown-set");
    render_set(&grown, 30);
    export(&grown, &dir.join("grown"), &flags);
    let grown = coco_splits(&dir.join("grown"));
    assert_eq!(grown.len(), 60);
    assert!(small.iter().all(|(image, split)| grown[image] == *split), "an image changed split as the set grew");
}

#[test]
fn webdataset_shards_hold_every_sample_as_gnu_tar_reads_them() {
    let out = scratch("export-wds").join("wds");
    export(set(), &out, &["--format", "webdataset", "--shard-size", "1", "--val-fraction", "0.2"]);
    let (images, by_image) = coco_of(set());
    let shards: Vec<PathBuf> = tree(&out).keys().map(|k| out.join(k)).collect();
    assert!(shards.iter().all(|s| s.extension().unwrap() == "tar") && shards.len() >= 3, "{shards:?}");
    let mut members = Vec::new();
    for shard in &shards {
        let list = std::process::Command::new("tar").arg("-tf").arg(shard).output().unwrap();
        assert!(list.status.success(), "GNU tar refuses {}", shard.display());
        members.extend(String::from_utf8(list.stdout).unwrap().lines().map(String::from));
        let unpack = scratch(&format!("export-wds-{}", shard.file_stem().unwrap().to_string_lossy()));
        assert!(std::process::Command::new("tar")
            .arg("-xf")
            .arg(shard)
            .arg("-C")
            .arg(&unpack)
            .status()
            .unwrap()
            .success());
        for (name, bytes) in tree(&unpack) {
            let key = name.split('.').next().unwrap().to_string();
            let image = &images[&format!("images/{key}.png")];
            let annotations = &by_image[&image["id"].as_u64().unwrap()];
            let source = match &name[key.len()..] {
                ".png" => format!("images/{key}.png"),
                ".mask.png" => {
                    assert_mask_holds(&bytes, annotations, &name);
                    format!("masks/{key}.png")
                }
                ".depth.exr" => format!("depth/{key}.exr"),
                ".json" => {
                    // The image and its annotations (boxes, areas, RLEs and all) as the COCO file has them.
                    let meta: Value = serde_json::from_slice(&bytes).unwrap();
                    assert_eq!(&meta["image"], image, "{name}");
                    assert_eq!(meta["annotations"].as_array().unwrap(), annotations, "{name}");
                    continue;
                }
                other => panic!("unexpected member {other}"),
            };
            assert!(bytes == std::fs::read(set().join(source)).unwrap(), "{name}");
        }
    }
    assert_eq!(members.len(), 20 * 4, "four files per image");
}

#[test]
fn hf_metadata_lists_every_image_with_its_objects() {
    let out = scratch("export-hf").join("hf");
    export(set(), &out, &["--format", "hf", "--val-fraction", "0.3"]);
    let (images, by_image) = coco_of(set());
    let mut rows = 0;
    for split in ["train", "validation"] {
        let text = std::fs::read_to_string(out.join(split).join("metadata.jsonl")).unwrap();
        for line in text.lines() {
            let row: Value = serde_json::from_str(line).unwrap();
            assert!(out.join(split).join(row["file_name"].as_str().unwrap()).is_file());
            let file = row["file_name"].as_str().unwrap();
            let annotations = &by_image[&images[&format!("images/{file}")]["id"].as_u64().unwrap()];
            assert_eq!(row["image_id"], annotations[0]["image_id"]);
            let mask = std::fs::read(out.join(split).join(row["mask_file_name"].as_str().unwrap())).unwrap();
            assert!(mask == std::fs::read(set().join(format!("masks/{file}"))).unwrap());
            assert_mask_holds(&mask, annotations, file);
            // Each object column, row by row, is the COCO annotations' field, in their order;
            // the class label counts from 0 where COCO's one category is id 1.
            let objects = &row["objects"];
            for (column, field) in [
                ("id", "id"),
                ("bbox", "bbox"),
                ("area", "area"),
                ("segmentation", "segmentation"),
                ("iscrowd", "iscrowd"),
                ("mask_id", "mask_id"),
            ] {
                let want: Vec<&Value> = annotations.iter().map(|a| &a[field]).collect();
                let got: Vec<&Value> = objects[column].as_array().unwrap().iter().collect();
                assert_eq!(got, want, "{file}: objects.{column}");
            }
            let categories: Vec<u64> = annotations.iter().map(|a| a["category_id"].as_u64().unwrap() - 1).collect();
            assert_eq!(objects["category"], serde_json::json!(categories), "{file}");
            rows += 1;
        }
    }
    assert_eq!(rows, 20);
    assert!(!out.join("test").exists(), "no test split asked for");
    // The card names the splits' folders and the category, as `load_dataset(OUT)` reads them.
    let card = std::fs::read_to_string(out.join("README.md")).unwrap();
    for needed in [
        "- split: train\n    path: train/**",
        "- split: validation",
        "'0': \"mushroom\"",
        "- name: mask\n    dtype: image",
    ] {
        assert!(card.contains(needed), "{needed}: {card}");
    }
}

#[test]
fn bad_export_arguments_print_one_error_line_and_write_nothing() {
    let dir = scratch("export-bad");
    let before = tree(set());
    let unfinished = dir.join("unfinished");
    let half = [
        "dataset",
        "--render-only",
        "--out",
        unfinished.to_str().unwrap(),
        "--count",
        "2",
        "--width",
        "160",
        "--height",
        "128",
        "--shard",
        "0/2",
    ];
    assert!(vkdiff(&half).status.success());
    let foreign = dir.join("foreign");
    std::fs::create_dir_all(&foreign).unwrap();
    std::fs::write(foreign.join("notes.txt"), "mine").unwrap();
    let existing = dir.join("existing");
    std::fs::create_dir_all(&existing).unwrap();
    let out = dir.join("out");
    let (dataset, out_s) = (set().to_str().unwrap(), out.to_str().unwrap());
    let inside = format!("{dataset}/exports");
    for (args, message) in [
        (vec![unfinished.to_str().unwrap(), "--format", "coco", "--out", out_s], "no annotations.json yet"),
        (vec![foreign.to_str().unwrap(), "--format", "coco", "--out", out_s], "not a vkdiff dataset folder"),
        (
            vec![dataset, "--format", "coco", "--out", out_s, "--val-fraction", "-0.1"],
            "--val-fraction -0.1 must lie in [0, 1)",
        ),
        (
            vec![dataset, "--format", "coco", "--out", out_s, "--test-fraction", "1"],
            "--test-fraction 1 must lie in [0, 1)",
        ),
        (
            vec![dataset, "--format", "yolo", "--out", out_s, "--val-fraction", "0.6", "--test-fraction", "0.5"],
            "leave nothing to train on",
        ),
        (vec![dataset, "--format", "hf", "--out", existing.to_str().unwrap()], "exists: give --force"),
        (vec![dataset, "--format", "coco", "--out", &inside], "overlaps the dataset folder"),
        (
            vec![dataset, "--format", "webdataset", "--out", out_s, "--shard-size", "0"],
            "--shard-size must be at least 1",
        ),
    ] {
        let mut full = vec!["dataset", "export"];
        full.extend(&args);
        let result = vkdiff(&full);
        let stderr = String::from_utf8_lossy(&result.stderr);
        let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error")).collect();
        assert!(!result.status.success() && errors.len() == 1 && errors[0].contains(message), "{args:?}: {stderr}");
        assert!(!out.exists() && !Path::new(&inside).exists(), "{args:?} wrote its output");
    }
    assert_eq!(std::fs::read_dir(&existing).unwrap().count(), 0);
    let hidden: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with('.'))
        .collect();
    assert!(hidden.is_empty(), "a refused export left {hidden:?}");
    // --force replaces the folder whole; the dataset folder is never written; what a killed
    // export left (its process gone) is removed.
    std::fs::write(existing.join("stale.txt"), "old").unwrap();
    let killed = dir.join(".existing.partial-4194999");
    std::fs::create_dir_all(killed.join("train")).unwrap();
    export(set(), &existing, &["--format", "hf", "--force", "--copy"]);
    assert!(!existing.join("stale.txt").exists() && existing.join("train/metadata.jsonl").is_file());
    assert!(!killed.exists(), "a killed export's folder was left");
    assert!(tree(set()) == before, "the export changed the dataset folder");
}

/// One scene cannot fill a val split: each format still gives its trainer what it needs.
#[test]
fn a_one_scene_set_exports_in_every_format() {
    let dir = scratch("export-one");
    let one = dir.join("set");
    render_set_of(&one, 1, 320, 256, 128);
    for format in ["coco", "yolo", "webdataset", "hf"] {
        export(&one, &dir.join(format), &["--format", format, "--val-fraction", "0.2"]);
    }
    let val = read_json(&dir.join("coco/val.json"));
    assert!(val["images"].as_array().unwrap().is_empty(), "an empty val.json is still COCO");
    let yaml = std::fs::read_to_string(dir.join("yolo/data.yaml")).unwrap();
    assert!(yaml.lines().any(|l| l == "val: images/train"), "{yaml}");
    assert_eq!(tree(&dir.join("webdataset")).keys().cloned().collect::<Vec<_>>(), ["train-000000.tar"]);
    assert!(!dir.join("hf/validation").exists(), "datasets refuses a split folder without images");
    assert!(dir.join("hf/train/metadata.jsonl").is_file());
}
