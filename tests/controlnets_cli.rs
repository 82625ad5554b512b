//! Several ControlNets from the command line: `--controlnet MODEL,control=KIND,scale=S,start=F,end=F`
//! repeated, with each control's image, held to diffusers' MultiControlNetModel latents
//! (tools/make_multi_controlnet_fixtures.py); the records that give the run back; and the
//! one-line refusals of controls no net can take.

mod cli;

use cli::{png_text, scratch, vkdiff};
use serde_json::Value;
use std::path::Path;

fn fixture(name: &str) -> String {
    format!("{}/tests/fixtures/{name}", env!("CARGO_MANIFEST_DIR"))
}

fn relative_l2(got: &[f32], want: &[f32]) -> f64 {
    let diff: f64 = got.iter().zip(want).map(|(&g, &w)| (g as f64 - w as f64).powi(2)).sum();
    diff.sqrt() / want.iter().map(|&w| (w as f64).powi(2)).sum::<f64>().sqrt()
}

fn text(v: &Value) -> String {
    v.as_str().map_or_else(|| v.to_string(), String::from)
}

/// The flags of a fixture case: the first net sees the depth control (its image given as
/// `--depth`), the second the edges (`--control-image edges=`), each with its own scale and range.
fn case_flags(case: &Value) -> Vec<String> {
    let mut flags: Vec<String> = vec!["--model".into(), fixture("pipeline/tiny-sdxl")];
    for key in ["prompt", "seed", "steps", "sampler", "width", "height"] {
        flags.extend([format!("--{key}"), text(&case[key])]);
    }
    flags.extend(["--cfg".into(), text(&case["guidance_scale"])]);
    let controls = case["controls"].as_array().unwrap();
    for (c, kind) in controls.iter().zip(["depth", "edges"]) {
        let model = fixture(&format!("workflow/{}", text(&c["model"])));
        let (scale, start, end) = (text(&c["scale"]), text(&c["start"]), text(&c["end"]));
        flags.extend(["--controlnet".into(), format!("{model},control={kind},scale={scale},start={start},end={end}")]);
    }
    let image = |k: usize| fixture(&format!("workflow/{}", text(&controls[k]["image"])));
    flags.extend(["--depth".into(), image(0), "--control-image".into(), format!("edges={}", image(1))]);
    flags
}

fn gen(flags: &[String], png: &Path, latents: &Path) -> std::process::Output {
    let mut args = vec!["gen", "--precision", "f32", "--out", png.to_str().unwrap()];
    args.extend(["--latents-out", latents.to_str().unwrap()]);
    args.extend(flags.iter().map(String::as_str));
    vkdiff(&args)
}

#[test]
fn two_controlnets_from_the_command_line_match_diffusers_and_record_each_net() {
    let dir = Path::new(&fixture("workflow")).to_path_buf();
    let json: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("multi_controlnet.json")).unwrap()).unwrap();
    let records = vkdiff_formats::SafeTensors::open(&dir.join("multi_controlnet.safetensors")).unwrap();
    let out = scratch("controlnets");
    for case in json["cases"].as_array().unwrap() {
        let name = text(&case["name"]);
        let (png, lat) = (out.join(format!("{name}.png")), out.join(format!("{name}.safetensors")));
        let result = gen(&case_flags(case), &png, &lat);
        assert!(result.status.success(), "{name}: {}", String::from_utf8_lossy(&result.stderr));
        let (_, want) = records.values(&text(&case["tensors"]["latents"])).unwrap();
        let (_, got) = vkdiff_formats::SafeTensors::open(&lat).unwrap().values("latents").unwrap();
        let err = relative_l2(&got, &want);
        eprintln!("{name}: latents rel L2 {err:.2e}");
        assert!(err <= 1e-5, "{name}: latents relative L2 error {err:.2e}");

        // Each net's control, scale and range, as the flag that gives it back and as A1111's
        // ControlNet extension lists its units.
        let chunks = png_text(&png);
        let get = |k: &str| chunks.iter().find(|(key, _)| key == k).map(|(_, v)| v.clone());
        let nets = get("controlnets").expect("a controlnets chunk");
        let c = case["controls"].as_array().unwrap();
        let lines: Vec<&str> = nets.lines().collect();
        assert_eq!(lines.len(), 2, "{nets}");
        for (line, (c, kind)) in lines.iter().zip(c.iter().zip(["depth", "edges"])) {
            let number = |k: &str| c[k].as_f64().unwrap();
            let (scale, start, end) = (number("scale") as f32, number("start"), number("end"));
            let tail = format!(",control={kind},scale={scale},start={start},end={end}");
            assert!(line.ends_with(&tail), "{line} does not end {tail}");
        }
        assert!(get("controlnet").is_none() && get("control_scale").is_none(), "one net's keys with two nets");
        let parameters = get("parameters").unwrap();
        assert!(
            parameters.contains("ControlNet 0: \"Module: depth, Model: controlnet, Weight: ")
                && parameters.contains("ControlNet 1: \"Module: edges, Model: controlnet-small, Weight: "),
            "{parameters}"
        );
        assert!(get("control_images").is_some_and(|v| v.starts_with("edges=")), "{chunks:?}");

        // The recorded flags give the same image back.
        let mut again = case_flags(case);
        for (value, line) in again.iter_mut().filter(|f| f.contains(",control=")).zip(&lines) {
            *value = line.to_string();
        }
        let (png2, lat2) = (out.join(format!("{name}-again.png")), out.join(format!("{name}-again.safetensors")));
        let result = gen(&again, &png2, &lat2);
        assert!(result.status.success(), "{name} again: {}", String::from_utf8_lossy(&result.stderr));
        assert_eq!(std::fs::read(&png).unwrap(), std::fs::read(&png2).unwrap(), "{name}: the recorded flags differ");
    }
}

#[test]
fn controls_no_controlnet_can_take_are_refused_in_one_line() {
    let dir = scratch("controlnets-bad");
    let out = dir.join("x.png");
    let model = fixture("pipeline/tiny-sdxl");
    let plain = fixture("workflow/controlnet");
    let depth = fixture("workflow/control.png");
    let edges = format!("edges={}", fixture("workflow/control-edges.png"));
    let both = format!("{plain},control=depth+edges");
    let unknown = format!("{plain},control=canny");
    let small_edges = format!("{},control=edges", fixture("workflow/controlnet-small"));
    for (args, message) in [
        (vec!["--controlnet", &both, "--depth", &depth, "--control-image", &edges], "ControlNet-Union"),
        (vec!["--controlnet", &unknown, "--depth", &depth], "control=canny: expected one of depth, edges"),
        (vec!["--controlnet", &plain, "--depth", &depth, "--control-image", &edges], "no --controlnet sees edges"),
        (vec!["--controlnet", &plain, "--controlnet", &small_edges, "--depth", &depth], "--control-image edges=FILE"),
        (vec!["--controlnet", &small_edges, "--control-image", "depth=x.png"], "--depth FILE"),
    ] {
        let mut all = vec!["gen", "--model", &model, "--prompt", "x", "--steps", "1", "--out", out.to_str().unwrap()];
        all.extend(["--width", "64", "--height", "64"]);
        all.extend(&args);
        let result = vkdiff(&all);
        let stderr = String::from_utf8_lossy(&result.stderr);
        let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
        assert!(result.status.code() == Some(2) && errors.len() == 1, "{args:?}: {stderr}");
        assert!(errors[0].contains(message), "{args:?}: {stderr}");
        assert!(!out.exists(), "{args:?} wrote {}", out.display());
    }
}

/// A set whose two ControlNets see the depth and the edges of each scene: the edges are made
/// with no `--controls` flag, each net is recorded in dataset.json and in the PNG, and `vkdiff gen`
/// given an image's recorded files and flags writes the very same PNG.
#[test]
fn a_sets_controlnets_see_their_scene_controls_and_gen_reproduces_its_images() {
    let dir = scratch("controlnets-set");
    let set = dir.join("set");
    let scenes = fixture("scenes/folders");
    let depth_net = format!("{},scale=0.7", fixture("workflow/controlnet"));
    let edges_net = format!("{},control=edges,scale=0.5,start=0.25", fixture("workflow/controlnet-small"));
    let shared = ["--model", &fixture("pipeline/tiny-sdxl"), "--steps", "4", "--precision", "f32"];
    let mut args = vec!["dataset", "--scenes", &scenes, "--count", "2", "--prompt", "an orchard"];
    args.extend(["--controlnet", &depth_net, "--controlnet", &edges_net, "--out", set.to_str().unwrap()]);
    args.extend(shared);
    let run = vkdiff(&args);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));

    let settings: Value = serde_json::from_slice(&std::fs::read(set.join("dataset.json")).unwrap()).unwrap();
    let settings = &settings["settings"];
    let nets = &settings["controlnets"];
    let net = |k: usize| (nets[k]["controls"].to_string(), nets[k]["scale"].as_f64(), nets[k]["start"].as_f64());
    assert_eq!(net(0), ("[\"depth\"]".to_string(), Some(0.7f32 as f64), Some(0.0)), "{settings}");
    assert_eq!(net(1), ("[\"edges\"]".to_string(), Some(0.5), Some(0.25)), "{settings}");
    assert_eq!(settings["controls"], serde_json::json!(["edges"]), "the edges are made for the second net");
    let coco: Value = serde_json::from_slice(&std::fs::read(set.join("annotations.json")).unwrap()).unwrap();
    for image in coco["images"].as_array().unwrap() {
        let edges = image["control_files"]["edges"].as_str().expect("the edges the second net sees");
        let png = set.join(image["file_name"].as_str().unwrap());
        let chunks = png_text(&png);
        let recorded = chunks.iter().find(|(k, _)| k == "controlnets").map(|(_, v)| v.clone()).unwrap();
        let out = dir.join(format!("gen-{}.png", image["id"]));
        let mut again = vec!["gen", "--out", out.to_str().unwrap(), "--seed"];
        let seed = image["seed"].to_string();
        again.extend([&seed, "--prompt", image["prompt"].as_str().unwrap()]);
        again.extend(["--depth", image["depth_file"].as_str().unwrap()]);
        let edges = format!("edges={edges}");
        again.extend(["--control-image", &edges]);
        for line in recorded.lines() {
            again.extend(["--controlnet", line]);
        }
        again.extend(shared);
        let result = cli::command().args(&again).current_dir(&set).output().unwrap();
        assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
        assert!(std::fs::read(&out).unwrap() == std::fs::read(&png).unwrap(), "gen did not reproduce {png:?}");
    }
}

/// ControlNet-Union by its Hugging Face id, as xinsir's repository holds it (the model and its
/// ProMax file side by side): one Union model seeing the depth and the edges, and two Union
/// models with their own controls and ranges, held to diffusers' Union pipeline latents
/// (tools/make_union_pipeline_fixtures.py) and recorded per net.
#[test]
fn union_controlnets_by_hugging_face_id_match_diffusers() {
    let dir = Path::new(&fixture("workflow")).to_path_buf();
    let json: Value = serde_json::from_str(&std::fs::read_to_string(dir.join("union_pipeline.json")).unwrap()).unwrap();
    let records = vkdiff_formats::SafeTensors::open(&dir.join("union_pipeline.safetensors")).unwrap();
    let out = scratch("controlnets-union");
    let repo = "vkdiff-test/controlnet-union-sdxl-1.0";
    // The fixture's union types as scene controls: 1 depth, 3 thin lines, 5 segment.
    let kind = |mode: u64| match mode {
        1 => "depth",
        3 => "edges",
        5 => "segmentation",
        other => panic!("no scene control for union type {other}"),
    };
    for case in json["cases"].as_array().unwrap() {
        let name = text(&case["name"]);
        let mut flags: Vec<String> = vec!["--model".into(), fixture("pipeline/tiny-sdxl")];
        for key in ["prompt", "seed", "steps", "sampler", "width", "height"] {
            flags.extend([format!("--{key}"), text(&case[key])]);
        }
        flags.extend(["--cfg".into(), text(&case["guidance_scale"])]);
        for net in case["nets"].as_array().unwrap() {
            let model = match text(&net["model"]).as_str() {
                "controlnet-union" => repo.to_string(),
                _ => format!("{repo}/diffusion_pytorch_model_promax.safetensors"),
            };
            let modes = net["modes"].as_array().unwrap();
            let controls: Vec<&str> = modes.iter().map(|m| kind(m.as_u64().unwrap())).collect();
            let (scale, start, end) = (text(&net["scale"]), text(&net["start"]), text(&net["end"]));
            let value = format!("{model},control={},scale={scale},start={start},end={end}", controls.join("+"));
            flags.extend(["--controlnet".into(), value]);
            for (control, image) in controls.iter().zip(net["images"].as_array().unwrap()) {
                let file = dir.join(text(image)).display().to_string();
                match *control {
                    "depth" => flags.extend(["--depth".into(), file]),
                    other => flags.extend(["--control-image".into(), format!("{other}={file}")]),
                }
            }
        }
        let (png, lat) = (out.join(format!("{name}.png")), out.join(format!("{name}.safetensors")));
        let mut args = vec!["gen", "--precision", "f32", "--out", png.to_str().unwrap()];
        args.extend(["--latents-out", lat.to_str().unwrap()]);
        args.extend(flags.iter().map(String::as_str));
        let hub = fixture("hub");
        let result = cli::vkdiff_with(&args, &[("HF_HUB_CACHE", &hub)]);
        assert!(result.status.success(), "{name}: {}", String::from_utf8_lossy(&result.stderr));
        let (_, want) = records.values(&text(&case["tensors"]["latents"])).unwrap();
        let (_, got) = vkdiff_formats::SafeTensors::open(&lat).unwrap().values("latents").unwrap();
        let err = relative_l2(&got, &want);
        eprintln!("{name}: latents rel L2 {err:.2e}");
        assert!(err <= 1e-5, "{name}: latents relative L2 error {err:.2e}");
        let chunks = png_text(&png);
        let recorded = chunks.iter().find(|(k, _)| k == "controlnets").map(|(_, v)| v.clone()).unwrap();
        assert!(recorded.lines().all(|l| l.starts_with(&format!("{repo}@"))), "{recorded}");
        assert_eq!(recorded.lines().count(), case["nets"].as_array().unwrap().len(), "{recorded}");
    }
}
