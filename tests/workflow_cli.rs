//! The paper's full workflow as a user runs it: `vkdiff gen` with a depth ControlNet, an
//! IP-Adapter over two style images and two LoRAs, held to diffusers' latents
//! (tools/make_workflow_fixtures.py, case `full`), and the guide flags' one-line errors.

mod cli;

use cli::{png_text, scratch, vkdiff};
use std::path::Path;

fn fixture(name: &str) -> String {
    format!("{}/tests/fixtures/{name}", env!("CARGO_MANIFEST_DIR"))
}

fn relative_l2(got: &[f32], want: &[f32]) -> f64 {
    let diff: f64 = got.iter().zip(want).map(|(&g, &w)| (g as f64 - w as f64).powi(2)).sum();
    diff.sqrt() / want.iter().map(|&w| (w as f64).powi(2)).sum::<f64>().sqrt()
}

/// The `full` case's flags, read from records.json so the test follows the fixture.
fn full_case_flags() -> (Vec<String>, String) {
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(fixture("workflow/records.json")).unwrap()).unwrap();
    let case = json["cases"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["name"] == "full")
        .expect("fixture has the full case")
        .clone();
    let s = |v: &serde_json::Value| match v {
        serde_json::Value::String(s) => s.clone(),
        other => other.to_string(),
    };
    let w = |name: &serde_json::Value| fixture(&format!("workflow/{}", s(name)));
    let mut flags: Vec<String> = ["--model", &fixture("pipeline/tiny-sdxl")].map(String::from).to_vec();
    for key in ["prompt", "negative_prompt", "seed", "steps", "sampler", "width", "height"] {
        flags.extend([format!("--{}", key.replace('_', "-")), s(&case[key])]);
    }
    flags.extend(["--cfg".into(), s(&case["guidance_scale"])]);
    let c = &case["control"];
    flags.extend([
        "--controlnet".into(),
        w(&c["model"]),
        "--depth".into(),
        w(&c["image"]),
        "--control-scale".into(),
        s(&c["scale"]),
    ]);
    flags.extend(["--control-start".into(), s(&c["start"]), "--control-end".into(), s(&c["end"])]);
    let ip = &case["ip"];
    flags.extend([
        "--ip-adapter".into(),
        w(&ip["adapter"]),
        "--image-encoder".into(),
        fixture("workflow/image_encoder"),
        "--ip-scale".into(),
        s(&ip["scale"]),
    ]);
    for image in ip["images"].as_array().unwrap() {
        flags.extend(["--ip-image".into(), w(image)]);
    }
    for lora in case["loras"].as_array().unwrap() {
        flags.extend(["--lora".into(), format!("{}:{}", w(&lora["file"]), s(&lora["strength"]))]);
    }
    (flags, s(&case["tensors"]["latents"]))
}

fn run_full_case(precision: &str, tol: f64) {
    let (flags, record) = full_case_flags();
    let dir = scratch(precision);
    let (png, lat) = (dir.join("full.png"), dir.join("full.safetensors"));
    let mut args: Vec<&str> =
        vec!["gen", "--precision", precision, "--out", png.to_str().unwrap(), "--latents-out", lat.to_str().unwrap()];
    args.extend(flags.iter().map(String::as_str));
    let result = vkdiff(&args);
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(result.status.success(), "{stderr}");
    assert!(
        stderr.contains("lora-kohya-ldm.safetensors") && stderr.contains("lora-peft.safetensors"),
        "no LoRA summary: {stderr}"
    );
    let records = vkdiff_formats::SafeTensors::open(Path::new(&fixture("workflow/records.safetensors"))).unwrap();
    let (_, want) = records.values(&record).unwrap();
    let (_, got) = vkdiff_formats::SafeTensors::open(&lat).unwrap().values("latents").unwrap();
    let err = relative_l2(&got, &want);
    assert!(err < tol, "{precision}: latents relative L2 error {err:.2e}");

    let text = png_text(&png);
    let get = |k: &str| {
        text.iter().find(|(key, _)| key == k).map(|(_, v)| v.clone()).unwrap_or_else(|| panic!("no `{k}` text chunk"))
    };
    let parameters = get("parameters");
    assert!(
        parameters.contains("ControlNet: ")
            && parameters.contains("IP-Adapter: ")
            && parameters.contains("<lora:lora-peft:0.5>"),
        "{parameters}"
    );
    assert_eq!(get("ip_images").lines().count(), 2);
    assert!(get("loras").contains("lora-peft.safetensors:0.5"), "{}", get("loras"));
}

#[test]
fn the_full_workflow_matches_diffusers_in_f32() {
    run_full_case("f32", 1e-4);
}

#[test]
fn the_full_workflow_matches_diffusers_in_f16() {
    run_full_case("f16", 2e-2);
}

#[test]
fn bad_guide_flags_print_one_error_line_and_write_nothing() {
    let dir = scratch("bad");
    let out = dir.join("x.png");
    let model = fixture("pipeline/tiny-sdxl");
    let controlnet = fixture("workflow/controlnet");
    let control = fixture("workflow/control.png");
    let lora = fixture("workflow/lora-peft.safetensors");
    let adapter = fixture("workflow/ip-adapter_tiny.safetensors");
    let encoder = fixture("workflow/image_encoder");
    let missing = dir.join("missing.png");
    let missing = missing.to_str().unwrap();
    for (args, message) in [
        (
            vec!["--controlnet", &controlnet, "--depth", &control, "--control-start", "0.8", "--control-end", "0.2"],
            "must satisfy 0 <= start < end <= 1",
        ),
        (vec!["--controlnet", &controlnet, "--depth", missing], "--depth"),
        (vec!["--controlnet", &lora, "--depth", &control], "not a ControlNet"),
        (vec!["--lora", &controlnet], "--lora"),
        (vec!["--lora", &fixture("workflow/controlnet-cldm.safetensors")], "--lora"),
        (vec!["--ip-adapter", &adapter, "--image-encoder", &encoder, "--ip-image", missing], "--ip-image"),
        (vec!["--ip-adapter", &lora, "--image-encoder", &encoder, "--ip-image", &control], "not an IP-Adapter"),
    ] {
        let result = vkdiff(
            &[
                &[
                    "gen",
                    "--model",
                    &model,
                    "--prompt",
                    "x",
                    "--steps",
                    "1",
                    "--width",
                    "64",
                    "--height",
                    "64",
                    "--out",
                    out.to_str().unwrap(),
                ][..],
                &args,
            ]
            .concat(),
        );
        let stderr = String::from_utf8_lossy(&result.stderr);
        let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
        assert!(!result.status.success() && errors.len() == 1 && errors[0].contains(message), "{args:?}: {stderr}");
        assert!(!out.exists(), "{args:?} wrote {}", out.display());
    }
    let result = vkdiff(&[
        "gen",
        "--model",
        &model,
        "--prompt",
        "x",
        "--out",
        out.to_str().unwrap(),
        "--controlnet",
        &controlnet,
    ]);
    assert!(
        !result.status.success() && String::from_utf8_lossy(&result.stderr).contains("--depth"),
        "--controlnet without --depth"
    );
}
