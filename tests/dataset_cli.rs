//! `vkdiff dataset` as a user runs it, on the tiny SDXL with the whole workflow (ControlNet,
//! IP-Adapter over two style sets of different sizes, two LoRAs, two prompts): the COCO file by
//! pycocotools' rules against the masks, crops exactly as `vkdiff scene` cuts them, every image
//! reproduced by `vkdiff gen`, and one folder whatever the batch size, the sharding or a kill.

mod cli;

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
    let mut command = Command::new(env!("CARGO_BIN_EXE_vkdiff"));
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

/// Batches of two give the folder of batches of one; so they do under a memory budget that holds
/// the weights, the recorded passes and a decode, but not all three at once (about 11, 1 and 5 MiB
/// with the tiny models): the passes are then freed before each decode and recorded again.
#[test]
fn batches_give_the_same_folder_with_or_without_room_to_keep_their_passes() {
    let recordings = |text: &str| {
        let count = text.split("(recorded ").nth(1).and_then(|t| t.split('×').next());
        count.and_then(|n| n.parse::<usize>().ok()).unwrap_or_else(|| panic!("no recording count: {text}"))
    };
    let mut counts = Vec::new();
    for budget in ["", "17M"] {
        let dir = scratch(&format!("dataset-batch{budget}")).join("set");
        let mut args = dataset_flags(&dir);
        args.extend(["--batch", "2"].map(String::from));
        counts.push(recordings(&run_ok(&args, &[("VKDIFF_MEMORY_BUDGET", budget)])));
        assert_same_folder(&dir, reference());
    }
    assert!(counts[1] > counts[0], "recordings with room and without: {counts:?}");
}

#[test]
fn two_shards_and_a_merge_give_the_one_run() {
    let dir = scratch("dataset-shards").join("set");
    let spawn = |extra: &[&str], env: &[(&str, &str)]| {
        let mut args = dataset_flags(&dir);
        args.extend(extra.iter().map(|s| s.to_string()));
        vk().args(&args).envs(env.iter().copied()).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap()
    };
    // Two processes on one folder at once: one told its shard, one taking it from Slurm.
    let first = spawn(&["--shard", "0/2"], &[]);
    let second =
        spawn(&[], &[("SLURM_ARRAY_TASK_ID", "8"), ("SLURM_ARRAY_TASK_MIN", "7"), ("SLURM_ARRAY_TASK_COUNT", "2")]);
    for child in [first, second] {
        let out = child.wait_with_output().unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    }
    let merged = vkdiff(&["dataset", "merge", dir.to_str().unwrap()]);
    assert!(merged.status.success(), "{}", String::from_utf8_lossy(&merged.stderr));
    assert_same_folder(&dir, reference());

    // A missing part and a part made with other settings are refused, naming them.
    let record = dir.join("records/000003.json");
    let aside = dir.join("aside.json");
    std::fs::rename(&record, &aside).unwrap();
    let refused = vkdiff(&["dataset", "merge", dir.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(
        !refused.status.success()
            && stderr.contains("1 of 6 images are not done")
            && stderr.contains("image 3 (scene 1)"),
        "{stderr}"
    );
    let text = std::fs::read_to_string(&aside).unwrap();
    let fingerprint = read_json(&aside)["fingerprint"].as_str().unwrap().to_string();
    std::fs::write(&record, text.replace(&fingerprint, "0123456789abcdef")).unwrap();
    let refused = vkdiff(&["dataset", "merge", dir.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(
        !refused.status.success() && stderr.contains("records/000003.json was made with other settings"),
        "{stderr}"
    );
    std::fs::rename(&aside, &record).unwrap();

    // So is a run with other settings into the folder, before it writes anything.
    let before = tree(&dir);
    let mut other = dataset_flags(&dir);
    other.extend(["--cfg", "3"].map(String::from));
    let refused = vk().args(&other).output().unwrap();
    let stderr = String::from_utf8_lossy(&refused.stderr);
    let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
    assert!(
        !refused.status.success() && errors.len() == 1 && errors[0].contains("--cfg was 5.0 there, 3.0 now"),
        "{stderr}"
    );
    assert!(tree(&dir) == before, "a refused run changed the folder");
}

#[test]
fn a_killed_run_resumes_to_the_same_folder() {
    let dir = scratch("dataset-kill").join("set");
    let mut child = vk().args(dataset_flags(&dir)).stdout(Stdio::null()).stderr(Stdio::null()).spawn().unwrap();
    let records = dir.join("records");
    let count = || {
        std::fs::read_dir(&records)
            .map_or(0, |d| d.flatten().filter(|e| !e.file_name().to_string_lossy().starts_with('.')).count())
    };
    while count() < 2 && child.try_wait().unwrap().is_none() {
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let done = count();
    assert!((2..IMAGES as usize).contains(&done), "the run was to be killed part-way, {done} images were done");
    assert!(!dir.join("annotations.json").exists());
    let log = run_ok(&dataset_flags(&dir), &[]);
    assert!(log.contains(&format!("{} to make, {done} already done", IMAGES as usize - done)), "{log}");
    assert_same_folder(&dir, reference());
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

#[test]
fn bad_dataset_arguments_print_one_error_line_and_write_nothing() {
    let dir = scratch("dataset-bad");
    let out = dir.join("set");
    let foreign = dir.join("foreign");
    std::fs::create_dir_all(&foreign).unwrap();
    std::fs::write(foreign.join("notes.txt"), "mine").unwrap();
    let model = fixture("pipeline/tiny-sdxl");
    let adapter = fixture("workflow/ip-adapter_tiny.safetensors");
    let encoder = fixture("workflow/image_encoder");
    let missing = dir.join("missing.png");
    let missing = missing.to_str().unwrap();
    let base = |out: &Path| {
        ["dataset", "--out", out.to_str().unwrap(), "--model", &model, "--width", "160", "--height", "128"]
            .map(String::from)
            .to_vec()
    };
    for (extra, message) in [
        (vec!["--prompt", "x", "--crops", "2", "--crop-size", "48"], "--crop-size 48 must be a multiple of 32"),
        (vec!["--prompt", "x", "--crops", "2", "--crop-size", "256"], "--crop-size 256 must lie in [1, 128]"),
        (vec!["--crops", "1"], "at least one prompt"),
        (vec!["--prompt", "x", "--prompts", missing], "--prompts"),
        (vec!["--prompt", "x", "--count", "0"], "--count must be at least 1"),
        (vec!["--prompt", "x", "--batch", "0"], "--batch must be at least 1"),
        (vec!["--prompt", "x", "--shard", "2/2"], "--shard 2/2"),
        (vec!["--prompt", "x", "--shards", "2"], "JOB_COMPLETION_INDEX"),
        (
            vec!["--prompt", "x", "--ip-adapter", &adapter, "--image-encoder", &encoder],
            "--ip-adapter needs style images",
        ),
        (
            vec!["--prompt", "x", "--ip-adapter", &adapter, "--image-encoder", &encoder, "--ip-set", missing],
            "--ip-image",
        ),
        (vec!["--prompt", "x", "--sampler", "ddim", "--scheduler", "karras"], "Karras"),
        (vec!["--prompt", "x", "--density", "-1"], "--density"),
        (vec!["--prompt", "x", "--init-strength", "0"], "--init-strength 0 must be in (0, 1]"),
        (vec!["--prompt", "(x:1.2.3)", "--prompt-syntax", "weighted"], "weight `1.2.3`"),
        (vec!["--render-only"], "--render-only makes the shaded renders the images: drop --model"),
        (vec!["--prompt", "x", "--min-free", "100T"], "--min-free keeps 100 TiB"),
        (vec!["--prompt", "x", "--min-free", "lots"], "lots: expected bytes"),
    ] {
        let mut args = base(&out);
        args.extend(extra.iter().map(|s| s.to_string()));
        let result = vk().args(&args).output().unwrap();
        let stderr = String::from_utf8_lossy(&result.stderr);
        let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error")).collect();
        assert!(!result.status.success() && errors.len() == 1 && errors[0].contains(message), "{extra:?}: {stderr}");
        assert!(!out.exists(), "{extra:?} wrote {}", out.display());
    }
    // A render-only set takes no diffusion flag: each is named, not ignored.
    for (flag, value) in [("--prompt", "x"), ("--negative-prompt", "x"), ("--init-strength", "0.5")] {
        let args = ["dataset", "--render-only", "--out", out.to_str().unwrap(), flag, value];
        let stderr = String::from_utf8_lossy(&vk().args(args).output().unwrap().stderr).into_owned();
        let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error")).collect();
        assert!(errors.len() == 1 && errors[0].contains("--render-only") && errors[0].contains(flag), "{stderr}");
        assert!(!out.exists(), "{flag} wrote {}", out.display());
    }
    let mut args = base(&foreign);
    args.extend(["--prompt", "x"].map(String::from));
    let result = vk().args(&args).output().unwrap();
    assert!(
        String::from_utf8_lossy(&result.stderr).contains("holds other files (notes.txt"),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    assert_eq!(std::fs::read_dir(&foreign).unwrap().count(), 1, "nothing written into someone else's folder");
    // A file where the folder should be: the OS's reason, said once.
    let file = dir.join("afile");
    std::fs::write(&file, "mine").unwrap();
    let mut args = base(&file);
    args.extend(["--prompt", "x"].map(String::from));
    let stderr = String::from_utf8_lossy(&vk().args(&args).output().unwrap().stderr).into_owned();
    assert!(stderr.lines().any(|l| l.starts_with("error:") && l.contains("afile")), "{stderr}");
    assert_eq!(stderr.matches("(os error").count(), 1, "the OS's reason repeated: {stderr}");
    let result = vkdiff(&["dataset", "merge", dir.to_str().unwrap()]);
    assert!(String::from_utf8_lossy(&result.stderr).contains("not a vkdiff dataset folder"));
}

/// The test set's flags as an arguments file, as the deploy scripts read them.
fn args_file(dir: &Path) -> PathBuf {
    let flags = dataset_flags(Path::new("unused"));
    let path = dir.join("dataset.args");
    std::fs::write(&path, format!("# the test set\n\n{}\n", flags[3..].join("\n"))).unwrap();
    path
}

/// `script` run by `shell` with the deploy scripts' variables and `env`.
fn deploy(shell: &str, script: &[&str], dir: &Path, args: &Path, env: &[(&str, &str)]) -> std::process::Child {
    let mut command = Command::new(shell);
    command.args(script).current_dir(env!("CARGO_MANIFEST_DIR"));
    for var in [
        "SLURM_ARRAY_TASK_ID",
        "SLURM_ARRAY_TASK_MIN",
        "SLURM_ARRAY_TASK_COUNT",
        "SLURM_ARRAY_TASK_STEP",
        "JOB_COMPLETION_INDEX",
    ] {
        command.env_remove(var);
    }
    command.envs([
        // The jobs refuse a CPU device, and CI has only lavapipe.
        ("VKDIFF_REQUIRE_GPU", "0"),
        ("VKDIFF", env!("CARGO_BIN_EXE_vkdiff")),
        ("DATASET_DIR", dir.to_str().unwrap()),
        ("DATASET_ARGS", args.to_str().unwrap()),
    ]);
    command.envs(env.iter().copied()).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap()
}

fn wait_ok(child: std::process::Child) {
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
}

#[test]
fn the_slurm_array_and_its_merge_make_the_one_run() {
    let root = scratch("dataset-slurm");
    let (dir, args) = (root.join("set"), args_file(&root));
    for task in ["3", "4"] {
        let env = [("SLURM_ARRAY_TASK_ID", task), ("SLURM_ARRAY_TASK_MIN", "3"), ("SLURM_ARRAY_TASK_COUNT", "2")];
        wait_ok(deploy("bash", &["deploy/slurm/dataset.sbatch"], &dir, &args, &env));
    }
    std::fs::remove_file(dir.join("annotations.json")).unwrap(); // the last task merged; so must the merge job
    wait_ok(deploy("bash", &["deploy/slurm/merge.sbatch"], &dir, &args, &[]));
    assert_same_folder(&dir, reference());
}

/// A stand-in `scontrol` on PATH that notes its arguments in `root/scontrol.log`; the PATH.
fn fake_scontrol(root: &Path) -> String {
    let bin = root.join("bin");
    std::fs::create_dir_all(&bin).unwrap();
    let script = bin.join("scontrol");
    std::fs::write(&script, format!("#!/bin/sh\necho \"$@\" >> {}/scontrol.log\n", root.display())).unwrap();
    std::fs::set_permissions(&script, std::os::unix::fs::PermissionsExt::from_mode(0o755)).unwrap();
    format!("{}:{}", bin.display(), std::env::var("PATH").unwrap_or_default())
}

#[test]
fn the_slurm_task_refuses_a_node_without_a_gpu_driver_and_requeues() {
    let root = scratch("dataset-slurm-cpu");
    let (dir, args) = (root.join("set"), args_file(&root));
    let path = fake_scontrol(&root);
    let env = [("VKDIFF_REQUIRE_GPU", ""), ("PATH", &path), ("SLURM_JOB_ID", "4242")];
    let out = deploy("bash", &["deploy/slurm/dataset.sbatch"], &dir, &args, &env).wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.code() == Some(3) && stderr.contains("error: a GPU is required"), "{stderr}");
    assert!(!dir.join("annotations.json").exists());
    // A device failure may pass on another node: the task is requeued.
    let log = std::fs::read_to_string(root.join("scontrol.log")).unwrap_or_default();
    assert_eq!(log.trim(), "requeue 4242", "{stderr}");
}

#[test]
fn the_slurm_task_fails_bad_input_without_requeueing() {
    let root = scratch("dataset-slurm-bad");
    let dir = root.join("set");
    let args = root.join("bad.args");
    std::fs::write(&args, "--crop-size\n48\n--crops\n2\n--prompt\nx\n--model\n/nowhere\n").unwrap();
    let path = fake_scontrol(&root);
    let env = [("PATH", path.as_str()), ("SLURM_JOB_ID", "4243")];
    let out = deploy("bash", &["deploy/slurm/dataset.sbatch"], &dir, &args, &env).wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(!root.join("scontrol.log").exists(), "bad input was requeued: {stderr}");
}

#[test]
fn the_kubernetes_job_fails_at_once_on_bad_input() {
    // podFailurePolicy: exit 2 fails the Job; it needs restartPolicy Never.
    let yaml =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("deploy/kubernetes/dataset-job.yaml"))
            .unwrap();
    let rules: String = yaml.lines().skip_while(|l| !l.contains("podFailurePolicy:")).take(12).collect();
    assert!(rules.contains("action: FailJob") && rules.contains("values: [2]"), "{rules}");
    assert!(rules.contains("containerName: vkdiff") && yaml.contains("- name: vkdiff\n"), "{rules}");
    assert!(yaml.contains("restartPolicy: Never") && !yaml.contains("restartPolicy: OnFailure"));
}

#[test]
fn the_kubernetes_indexed_job_makes_the_one_run() {
    let root = scratch("dataset-k8s");
    let (dir, args) = (root.join("set"), args_file(&root));
    // The pod's shell script, as the Job's container runs it.
    let yaml =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("deploy/kubernetes/dataset-job.yaml"))
            .unwrap();
    let lines: Vec<&str> = yaml.lines().collect();
    let start = lines.iter().position(|l| l.trim() == "- |").expect("the Job runs a script") + 1;
    let indent = lines[start].len() - lines[start].trim_start().len();
    let script: Vec<&str> =
        lines[start..].iter().take_while(|l| l.len() - l.trim_start().len() >= indent).map(|l| &l[indent..]).collect();
    let script = script.join("\n");
    let pods: Vec<_> = ["0", "1"]
        .iter()
        .map(|&index| deploy("sh", &["-c", &script], &dir, &args, &[("JOB_COMPLETION_INDEX", index), ("SHARDS", "2")]))
        .collect();
    pods.into_iter().for_each(wait_ok);
    assert_same_folder(&dir, reference());
}
