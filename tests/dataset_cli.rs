//! `vkdiff dataset` as a user runs it, on the tiny SDXL with the whole workflow (ControlNet,
//! IP-Adapter over two style sets of different sizes, two LoRAs, two prompts): the COCO file by
//! pycocotools' rules against the masks, crops exactly as `vkdiff scene` cuts them, every image
//! reproduced by `vkdiff gen`, and one folder whatever the batch size, the sharding or a kill.

mod cli;
#[path = "dataset_cli/deploy.rs"]
mod deploy;
#[path = "dataset_cli/few_step.rs"]
mod few_step;
#[path = "dataset_cli/refusals.rs"]
mod refusals;
#[path = "dataset_cli/runs.rs"]
mod runs;

use cli::{scratch, vkdiff};
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use vkdiff_render::rle::Rle;

fn fixture(name: &str) -> String {
    format!("{}/tests/fixtures/{name}", env!("CARGO_MANIFEST_DIR"))
}

const SCENES: u64 = 3;
const IMAGES: u64 = 6;

/// The model and workflow flags, as `vkdiff gen` takes them too.
fn model_flags() -> Vec<String> {
    let w = |n: &str| fixture(&format!("workflow/{n}"));
    [
        "--model",
        &fixture("pipeline/tiny-sdxl"),
        "--steps",
        "3",
        "--sampler",
        "euler_a",
        "--negative-prompt",
        "blurry, low quality",
        "--controlnet",
        &w("controlnet"),
        "--control-scale",
        "0.7",
        "--ip-adapter",
        &w("ip-adapter_tiny.safetensors"),
        "--image-encoder",
        &w("image_encoder"),
        "--lora",
        &format!("{}:0.5", w("lora-peft.safetensors")),
        "--lora",
        &format!("{}:0.8", w("lora-kohya-ldm.safetensors")),
    ]
    .map(String::from)
    .to_vec()
}

/// Three scenes of 160×128, two 64² crops each, two prompts and two style sets.
fn dataset_flags(out: &Path) -> Vec<String> {
    let style = |n: &str| fixture(&format!("workflow/style-{n}.png"));
    let mut flags: Vec<String> = [
        "dataset",
        "--out",
        out.to_str().unwrap(),
        "--count",
        "3",
        "--seed",
        "5",
        "--width",
        "160",
        "--height",
        "128",
        "--crops",
        "2",
        "--crop-size",
        "64",
    ]
    .map(String::from)
    .to_vec();
    flags.extend(
        ["--prompt", "white button mushrooms, top-down photo", "--prompt", "brown caps on dark compost"]
            .map(String::from),
    );
    flags.extend(["--ip-set".into(), style("1"), "--ip-set".into(), format!("{},{}", style("1"), style("2"))]);
    flags.extend(model_flags());
    flags
}

/// The binary, shielded from a Slurm or Kubernetes job the tests may themselves run in.
fn vk() -> Command {
    shielded(Command::new(env!("CARGO_BIN_EXE_vkdiff")))
}

/// `command` without the variables by which a Slurm array or Kubernetes indexed job gives a
/// process its shard.
fn shielded(mut command: Command) -> Command {
    for var in [
        "SLURM_ARRAY_TASK_ID",
        "SLURM_ARRAY_TASK_MIN",
        "SLURM_ARRAY_TASK_COUNT",
        "SLURM_ARRAY_TASK_STEP",
        "JOB_COMPLETION_INDEX",
    ] {
        command.env_remove(var);
    }
    command
}

fn run_ok(args: &[String], env: &[(&str, &str)]) -> String {
    let out = vk().args(args).envs(env.iter().copied()).output().unwrap();
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{args:?}: {text}");
    text
}

/// One uninterrupted run at --batch 1: what every other way of making the set must equal.
fn reference() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = scratch("dataset-reference").join("set");
        run_ok(&dataset_flags(&dir), &[]);
        dir
    })
}

/// How many images of the set at `dir` are finished (their records written).
fn finished_images(dir: &Path) -> usize {
    std::fs::read_dir(dir.join("records"))
        .map_or(0, |d| d.flatten().filter(|e| !e.file_name().to_string_lossy().starts_with('.')).count())
}

/// Every file below `dir` (hidden ones too), by relative path.
fn tree(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeMap<String, Vec<u8>>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                walk(root, &path, out);
            } else {
                out.insert(path.strip_prefix(root).unwrap().display().to_string(), std::fs::read(&path).unwrap());
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

fn assert_same_folder(got: &Path, want: &Path) {
    let (got, want) = (tree(got), tree(want));
    assert_eq!(got.keys().collect::<Vec<_>>(), want.keys().collect::<Vec<_>>(), "the folders hold different files");
    for (name, bytes) in &want {
        assert!(&got[name] == bytes, "{name} differs");
    }
}

fn read_json(path: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

fn png_info(path: &Path) -> (u32, u32, png::ColorType, png::BitDepth, Vec<u8>) {
    let mut reader =
        png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap())).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let frame = reader.next_frame(&mut buf).unwrap();
    buf.truncate(frame.buffer_size());
    (frame.width, frame.height, frame.color_type, frame.bit_depth, buf)
}

#[test]
fn annotations_follow_coco_and_match_the_masks() {
    let dir = reference();
    let coco = read_json(&dir.join("annotations.json"));
    let images = coco["images"].as_array().unwrap();
    assert_eq!(images.len() as u64, IMAGES);
    assert_eq!(coco["categories"], serde_json::json!([{"id": 1, "name": "mushroom", "supercategory": "mushroom"}]));
    let annotations = coco["annotations"].as_array().unwrap();
    let ids: Vec<u64> = annotations.iter().map(|a| a["id"].as_u64().unwrap()).collect();
    assert_eq!(ids, (1..=annotations.len() as u64).collect::<Vec<_>>(), "annotation ids unique, from 1, in order");
    let mut styles = std::collections::BTreeSet::new();
    for (k, image) in images.iter().enumerate() {
        assert_eq!(image["id"], k as u64 + 1, "image ids unique and from 1");
        let (w, h) = (image["width"].as_u64().unwrap() as u32, image["height"].as_u64().unwrap() as u32);
        let (pw, ph, color, _, _) = png_info(&dir.join(image["file_name"].as_str().unwrap()));
        assert_eq!((pw, ph, color), (w, h, png::ColorType::Rgb), "{}: size as annotated", image["file_name"]);
        let (mw, mh, mcolor, mdepth, bytes) = png_info(&dir.join(image["mask_file"].as_str().unwrap()));
        assert_eq!((mw, mh, mcolor, mdepth), (w, h, png::ColorType::Grayscale, png::BitDepth::Sixteen));
        let mask: Vec<u16> = bytes.chunks(2).map(|b| u16::from_be_bytes([b[0], b[1]])).collect();
        assert!(
            dir.join(image["depth_file"].as_str().unwrap()).is_file()
                && image["seed"].is_u64()
                && image["scene_seed"] == 5 + k as u64 / 2
        );
        assert_eq!(image["crop"]["index"], k as u64 % 2);
        styles.insert(image["ip_images"].as_array().unwrap().len());
        let mine: Vec<&Value> = annotations.iter().filter(|a| a["image_id"] == image["id"]).collect();
        assert_eq!(mine.len(), *mask.iter().max().unwrap() as usize, "one annotation per instance in the mask");
        for a in mine {
            let id = a["mask_id"].as_u64().unwrap() as u16;
            let seg = &a["segmentation"];
            assert_eq!(seg["size"], serde_json::json!([h, w]));
            let decoded = Rle::from_coco_string(seg["counts"].as_str().unwrap(), h, w).unwrap().to_mask();
            let mut area = 0;
            let (mut x0, mut y0, mut x1, mut y1) = (u32::MAX, u32::MAX, 0, 0);
            for y in 0..h {
                for x in 0..w {
                    let inside = mask[(y * w + x) as usize] == id;
                    assert_eq!(decoded[(y * w + x) as usize], inside, "RLE of mask {id} at ({x}, {y})");
                    if inside {
                        area += 1;
                        (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
                    }
                }
            }
            assert_eq!(a["area"], area);
            assert_eq!(a["bbox"], serde_json::json!([x0, y0, x1 - x0 + 1, y1 - y0 + 1]));
            assert_eq!((a["iscrowd"].as_u64(), a["category_id"].as_u64()), (Some(0), Some(1)));
        }
    }
    assert_eq!(styles.len(), 2, "both style sets were chosen");
}

#[test]
fn gen_reproduces_every_image_byte_for_byte() {
    assert_gen_reproduces(reference());
}

#[test]
fn img2img_from_the_shaded_render_is_reproduced_by_gen() {
    let dir = scratch("dataset-init").join("set");
    let mut args = dataset_flags(&dir);
    let count = args.iter().position(|a| a == "--count").unwrap() + 1;
    args[count] = "1".into();
    args.extend(["--init-strength", "0.67"].map(String::from));
    run_ok(&args, &[]);
    let coco = read_json(&dir.join("annotations.json"));
    for image in coco["images"].as_array().unwrap() {
        assert_eq!((image["init_file"].as_str().is_some(), image["strength"].as_f64()), (true, Some(0.67)), "{image}");
        let init = vkdiff_pipeline::images::read_image(&dir.join(image["init_file"].as_str().unwrap())).unwrap();
        let control = vkdiff_pipeline::images::read_image(&dir.join(image["control_file"].as_str().unwrap())).unwrap();
        assert_eq!((init.width, init.height), (control.width, control.height));
        assert!(init.pixels != control.pixels, "the init image is the shaded render, not the control image");
    }
    // The shaded renders are those `vkdiff scene` writes for the same scene's crops.
    let scene = scratch("dataset-init-scene").join("5");
    run_ok(&scene_args(5, &scene), &[]);
    for k in 0..2 {
        let init = std::fs::read(dir.join(format!("init/{k:06}.png"))).unwrap();
        assert!(init == std::fs::read(scene.join(format!("crops/{k}/shaded.png"))).unwrap(), "init/{k:06}.png");
    }
    assert_render_only_is_the_init_images(&dir, &args);
    assert_gen_reproduces(&dir);
}

/// `--render-only` with the scene flags of the img2img set in `dir` (made with `args`): its
/// images are that set's init/ files byte for byte, with the same depth, masks and COCO.
fn assert_render_only_is_the_init_images(dir: &Path, args: &[String]) {
    let renders = dir.parent().unwrap().join("renders");
    let mut flags: Vec<String> =
        ["dataset", "--render-only", "--out", renders.to_str().unwrap()].map(String::from).to_vec();
    for flag in ["--count", "--seed", "--width", "--height", "--crops", "--crop-size"] {
        let at = args.iter().position(|a| a == flag).unwrap();
        flags.extend([flag.to_string(), args[at + 1].clone()]);
    }
    run_ok(&flags, &[]);
    let (diffused, rendered) = (read_json(&dir.join("annotations.json")), read_json(&renders.join("annotations.json")));
    assert_eq!(diffused["annotations"], rendered["annotations"]);
    let images = |coco: &Value| coco["images"].as_array().unwrap().clone();
    assert_eq!(images(&diffused).len(), images(&rendered).len());
    for (d, r) in images(&diffused).iter().zip(&images(&rendered)) {
        assert_eq!(r["source"], "render");
        for key in ["id", "file_name", "width", "height", "depth_file", "mask_file", "scene_seed", "crop", "camera"] {
            assert_eq!(d[key], r[key], "{key}");
        }
        let file =
            |dir: &Path, key: &str, entry: &Value| std::fs::read(dir.join(entry[key].as_str().unwrap())).unwrap();
        assert!(file(&renders, "file_name", r) == file(dir, "init_file", d), "{}", r["file_name"]);
        for key in ["depth_file", "control_file", "mask_file"] {
            assert!(file(&renders, key, r) == file(dir, key, d), "{}", r[key]);
        }
    }
}

#[test]
fn preview_stats_and_exports_read_a_diffusion_set() {
    let dir = reference();
    let out = scratch("dataset-look");
    let path = |name: &str| out.join(name).to_str().unwrap().to_string();
    let set = dir.to_str().unwrap().to_string();
    run_ok(&["dataset", "preview", &set, "--out", &path("page.html"), "--count", "3"].map(String::from), &[]);
    let page = std::fs::read_to_string(out.join("page.html")).unwrap();
    let coco = read_json(&dir.join("annotations.json"));
    let images = coco["images"].as_array().unwrap();
    assert_eq!(page.matches("<figure>").count(), 3);
    assert!(images.iter().any(|i| page.contains(&format!("seed {}", i["seed"]))), "captions carry the seeds");
    assert!(page.contains("white button mushrooms") || page.contains("brown caps"), "captions carry the prompts");
    let stats = run_ok(&["dataset", "stats", &set, "--json", "--charts", &path("charts")].map(String::from), &[]);
    let stats: Value = serde_json::from_str(&stats[..stats.rfind('}').unwrap() + 1]).unwrap();
    let sum = |v: &Value| v.as_object().unwrap().values().map(|n| n.as_u64().unwrap()).sum::<u64>();
    assert_eq!((sum(&stats["prompts"]), sum(&stats["style_sets"])), (IMAGES, IMAGES), "{stats}");
    assert_eq!(stats["image_seeds"].as_u64(), Some(IMAGES));
    run_ok(&["dataset", "export", &set, "--format", "hf", "--out", &path("hf")].map(String::from), &[]);
    let rows: Vec<Value> = ["train", "validation"]
        .iter()
        .filter_map(|s| std::fs::read_to_string(out.join("hf").join(s).join("metadata.jsonl")).ok())
        .flat_map(|text| text.lines().map(|l| serde_json::from_str::<Value>(l).unwrap()).collect::<Vec<_>>())
        .collect();
    assert_eq!(rows.len() as u64, IMAGES);
    assert!(rows.iter().all(|r| r["prompt"].is_string() && r["seed"].is_u64() && r["ip_images"].is_array()));
    run_ok(&["dataset", "export", &set, "--format", "yolo", "--out", &path("yolo")].map(String::from), &[]);
    let labels = ["train", "val"].iter().filter_map(|s| std::fs::read_dir(out.join("yolo/labels").join(s)).ok());
    assert_eq!(labels.map(|d| d.count() as u64).sum::<u64>(), IMAGES);
}

/// `vkdiff gen` with each image's recorded settings writes the very same PNG.
fn assert_gen_reproduces(dir: &Path) {
    let coco = read_json(&dir.join("annotations.json"));
    for image in coco["images"].as_array().unwrap() {
        let out = dir.parent().unwrap().join(format!("gen-{}.png", image["id"]));
        let mut args: Vec<String> = ["gen", "--out", out.to_str().unwrap()].map(String::from).to_vec();
        for (flag, key) in [("--depth", "depth_file"), ("--prompt", "prompt")] {
            args.extend([flag.to_string(), image[key].as_str().unwrap().to_string()]);
        }
        args.extend(["--seed".to_string(), image["seed"].to_string()]);
        if let Some(init) = image["init_file"].as_str() {
            args.extend([
                "--init-image".to_string(),
                init.to_string(),
                "--strength".to_string(),
                image["strength"].to_string(),
            ]);
        }
        for style in image["ip_images"].as_array().unwrap() {
            args.extend(["--ip-image".to_string(), style.as_str().unwrap().to_string()]);
        }
        args.extend(model_flags());
        let result = vk().args(&args).current_dir(dir).output().unwrap();
        assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
        let want = std::fs::read(dir.join(image["file_name"].as_str().unwrap())).unwrap();
        assert!(std::fs::read(&out).unwrap() == want, "vkdiff gen did not reproduce {}", image["file_name"]);
    }
}

/// `vkdiff scene` for scene `seed` as `dataset_flags` cuts it.
fn scene_args(seed: u64, out: &Path) -> Vec<String> {
    let seed = seed.to_string();
    let args = ["scene", "--seed", &seed, "--width", "160", "--height", "128", "--crops", "2", "--crop-size", "64"];
    let mut args: Vec<String> = args.map(String::from).to_vec();
    args.extend(["--out".into(), out.to_str().unwrap().into()]);
    args
}

#[test]
fn depth_control_and_masks_are_the_crops_vkdiff_scene_cuts() {
    let dir = reference();
    let scenes = scratch("dataset-scenes");
    for scene in 0..SCENES {
        let folder = scenes.join(scene.to_string());
        let seed = 5 + scene;
        run_ok(&scene_args(seed, &folder), &[]);
        for k in 0..2 {
            let stem = format!("{:06}", scene * 2 + k);
            for (ours, theirs) in [("depth", "depth.exr"), ("control", "control.png"), ("masks", "instances.png")] {
                let ext = Path::new(theirs).extension().unwrap().to_str().unwrap();
                let got = std::fs::read(dir.join(format!("{ours}/{stem}.{ext}"))).unwrap();
                assert!(
                    got == std::fs::read(folder.join(format!("crops/{k}/{theirs}"))).unwrap(),
                    "{ours}/{stem}.{ext} differs from scene {seed}'s crop {k}"
                );
            }
        }
    }
}

#[test]
fn whole_frames_are_cut_to_the_model_size_not_stretched() {
    let root = scratch("dataset-frames");
    let dir = root.join("set");
    let mut args: Vec<String> = [
        "dataset",
        "--out",
        dir.to_str().unwrap(),
        "--seed",
        "9",
        "--width",
        "150",
        "--height",
        "100",
        "--prompt",
        "mushrooms",
    ]
    .map(String::from)
    .to_vec();
    args.extend(model_flags().into_iter().take(10)); // the model, sampling and the ControlNet
    run_ok(&args, &[]);
    let image = &read_json(&dir.join("annotations.json"))["images"][0];
    assert_eq!(
        (image["width"].as_u64(), image["height"].as_u64()),
        (Some(128), Some(96)),
        "150×100 cut to multiples of 32"
    );
    assert_eq!(image["crop"]["offset_px"], serde_json::json!([11, 2]), "centred");
    assert_eq!(image["crop"]["index"], Value::Null);
    run_ok(
        &["scene", "--seed", "9", "--width", "150", "--height", "100", "--out", root.join("scene").to_str().unwrap()]
            .map(String::from),
        &[],
    );
    let (frame, fw, _) = vkdiff_pipeline::images::read_depth_exr(&root.join("scene/depth.exr")).unwrap();
    let (cut, w, h) = vkdiff_pipeline::images::read_depth_exr(&dir.join("depth/000000.exr")).unwrap();
    assert_eq!((w, h), (128, 96));
    for y in 0..h {
        assert!(
            cut[y * w..(y + 1) * w] == frame[(y + 2) * fw + 11..(y + 2) * fw + 11 + w],
            "depth row {y} is not the frame's"
        );
    }
}
