//! `vkdiff gen` as a user runs it, on the tiny SDXL pipeline (tools/make_pipeline_fixtures.py):
//! the PNG and latents files, their metadata, one-line errors that write nothing, and the VAE's
//! memory plan under a device memory budget (`VKDIFF_MEMORY_BUDGET`, enforced on every
//! allocation): diffusers' tiles when the whole decode would not fit, recorded in the PNG, and a
//! whole decode that cannot fit refused before any denoising.

mod cli;

use cli::{png_text, scratch, vkdiff};
use std::path::Path;
use std::process::{Command, Output};

fn fixture(name: &str) -> String {
    format!("{}/tests/fixtures/pipeline/{name}", env!("CARGO_MANIFEST_DIR"))
}

/// Recorded case 1 of records.json: euler, seed 42, 5 steps, cfg 7.5, 96×64, a negative prompt.
const CASE: [&str; 14] = [
    "--prompt",
    "a red bicycle leaning on a brick wall, golden hour",
    "--negative-prompt",
    "blurry, low quality",
    "--seed",
    "42",
    "--steps",
    "5",
    "--cfg",
    "7.5",
    "--width",
    "96",
    "--height",
    "64",
];

#[test]
fn gen_writes_the_image_and_latents_diffusers_wrote() {
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(fixture("records.json")).unwrap()).unwrap();
    let case = &json["gen"][1];
    assert_eq!(
        (case["prompt"].as_str(), case["negative_prompt"].as_str(), case["seed"].as_u64()),
        (Some(CASE[1]), Some(CASE[3]), Some(42)),
        "fixture case 1 changed"
    );
    let dir = scratch("case");
    let (png, lat) = (dir.join("bike.png"), dir.join("bike.safetensors"));
    let model = fixture("tiny-sdxl");
    let args = [
        &[
            "gen",
            "--model",
            &model,
            "--precision",
            "f32",
            "--out",
            png.to_str().unwrap(),
            "--latents-out",
            lat.to_str().unwrap(),
        ][..],
        &CASE,
    ]
    .concat();
    let result = vkdiff(&args);
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(stderr.contains("5/5") && stderr.contains("VAE: decoding"), "no progress shown: {stderr}");

    let records = vkdiff_formats::SafeTensors::open(Path::new(&fixture("records.safetensors"))).unwrap();
    let written = vkdiff_formats::SafeTensors::open(&lat).unwrap();
    let (shape, got) = written.values("latents").unwrap();
    let (want_shape, want) = records.values("gen.1.latents").unwrap();
    assert_eq!(shape, want_shape);
    let err: f64 = got.iter().zip(&want).map(|(&g, &w)| (g as f64 - w as f64).powi(2)).sum::<f64>().sqrt()
        / want.iter().map(|&w| (w as f64).powi(2)).sum::<f64>().sqrt();
    assert!(err < 1e-4, "latents relative L2 error {err:.2e}");

    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&png).unwrap()));
    let reader = decoder.read_info().unwrap();
    let info = reader.info();
    assert_eq!((info.width, info.height, info.color_type), (96, 64, png::ColorType::Rgb));
    let text = png_text(&png);
    let get = |k: &str| {
        text.iter().find(|(key, _)| key == k).map(|(_, v)| v.clone()).unwrap_or_else(|| panic!("no `{k}` text chunk"))
    };
    assert!(
        get("parameters").starts_with(&format!(
            "{}\nNegative prompt: {}\nSteps: 5, Sampler: Euler, CFG scale: 7.5, Seed: 42, Size: 96x64",
            CASE[1], CASE[3]
        )),
        "{}",
        get("parameters")
    );
    assert_eq!((get("seed"), get("sampler"), get("negative_prompt")), ("42".into(), "euler".into(), CASE[3].into()));
    assert!(!dir.join("bike.png.partial").exists());
}

#[test]
fn bad_gen_arguments_print_one_error_line_and_write_nothing() {
    let dir = scratch("bad");
    let out = dir.join("x.png");
    let out_arg = out.to_str().unwrap();
    let model = fixture("tiny-sdxl");
    let missing = dir.join("missing");
    let workflow = |f: &str| format!("{}/tests/fixtures/workflow/{f}", env!("CARGO_MANIFEST_DIR"));
    let (adapter, encoder) = (workflow("ip-adapter_tiny.safetensors"), workflow("image_encoder"));
    let init = format!("{}/tests/fixtures/compat/init-64.png", env!("CARGO_MANIFEST_DIR"));
    for (args, message) in [
        (vec!["--model", missing.to_str().unwrap()], "--model"),
        (vec!["--model", &model, "--width", "100"], "--width 100 must be a positive multiple of 32 for this model"),
        (vec!["--model", &model, "--sampler", "dpmpp_2m_sde"], "unknown sampler `dpmpp_2m_sde`"),
        (
            vec!["--model", &model, "--sampler", "ddim", "--scheduler", "karras"],
            "Karras sigmas are not available with ddim",
        ),
        (vec!["--model", &model, "--steps", "0"], "needs at least 1 step"),
        (vec!["--model", &model, "--original-size", "1024"], "not WIDTHxHEIGHT"),
        (vec!["--model", &model, "--crops-coords-top-left", "0;0"], "not TOP,LEFT"),
        (vec!["--model", &model, "--init-image", &init, "--strength", "1.5"], "--strength 1.5 must be in (0, 1]"),
        (
            vec!["--model", &model, "--init-image", &init, "--strength", "0.2", "--steps", "4"],
            "runs none of them; raise --steps or --strength",
        ),
        (vec!["--model", &model, "--init-image", missing.to_str().unwrap()], "--init-image"),
        (
            vec!["--model", &model, "--prompt-syntax", "weighted", "--negative-prompt", "BREAK it"],
            "BREAK is not supported",
        ),
        (
            vec![
                "--model",
                &model,
                "--ip-adapter",
                &adapter,
                "--image-encoder",
                &encoder,
                "--ip-image",
                &init,
                "--ip-scale",
                "up.7=1",
            ],
            "--ip-scale up.7: this UNet has no cross-attention there",
        ),
        (
            vec![
                "--model",
                &model,
                "--ip-adapter",
                &adapter,
                "--image-encoder",
                &encoder,
                "--ip-image",
                &init,
                "--ip-scale",
                "sideways=1",
            ],
            "name a block as",
        ),
        (
            vec![
                "--model",
                &model,
                "--ip-adapter",
                &adapter,
                "--image-encoder",
                &encoder,
                "--ip-image",
                &init,
                "--ip-mode",
                "style",
                "--ip-scale",
                "up.0=1",
            ],
            "--ip-mode gives the blocks",
        ),
    ] {
        let result = vkdiff(&[&["gen", "--prompt", "x", "--out", out_arg][..], &args].concat());
        let stderr = String::from_utf8_lossy(&result.stderr);
        let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
        assert!(!result.status.success() && errors.len() == 1 && errors[0].contains(message), "{args:?}: {stderr}");
        assert!(!out.exists(), "{args:?} wrote {out_arg}");
    }
    let result = vkdiff(&["gen", "--model", &model, "--prompt", "x", "--out", dir.join("x.jpg").to_str().unwrap()]);
    assert!(String::from_utf8_lossy(&result.stderr).contains("give a .png path"));
}

#[test]
fn gen_img2img_writes_the_latents_diffusers_wrote() {
    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(format!("{}/tests/fixtures/compat/records.json", env!("CARGO_MANIFEST_DIR"))).unwrap(),
    )
    .unwrap();
    let case = json["cases"].as_array().unwrap().iter().find(|c| c["name"] == "img2img_euler_a").unwrap();
    let dir = scratch("img2img");
    let (png, lat) = (dir.join("barn.png"), dir.join("barn.safetensors"));
    let init = format!("{}/tests/fixtures/compat/{}", env!("CARGO_MANIFEST_DIR"), case["init"].as_str().unwrap());
    let (seed, steps, strength) = (case["seed"].to_string(), case["steps"].to_string(), case["strength"].to_string());
    let result = vkdiff(&[
        "gen",
        "--model",
        &fixture("tiny-sdxl"),
        "--precision",
        "f32",
        "--prompt",
        case["prompt"].as_str().unwrap(),
        "--seed",
        &seed,
        "--steps",
        &steps,
        "--sampler",
        "euler_a",
        "--init-image",
        &init,
        "--strength",
        &strength,
        "--out",
        png.to_str().unwrap(),
        "--latents-out",
        lat.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(result.status.success(), "{stderr}");
    assert!(stderr.contains("3/3"), "img2img at strength 0.75 of 4 steps runs 3: {stderr}");
    let records = vkdiff_formats::SafeTensors::open(Path::new(&format!(
        "{}/tests/fixtures/compat/records.safetensors",
        env!("CARGO_MANIFEST_DIR")
    )))
    .unwrap();
    let (_, want) = records.values(case["tensors"]["latents"].as_str().unwrap()).unwrap();
    let (_, got) = vkdiff_formats::SafeTensors::open(&lat).unwrap().values("latents").unwrap();
    let err: f64 = got.iter().zip(&want).map(|(&g, &w)| (g as f64 - w as f64).powi(2)).sum::<f64>().sqrt()
        / want.iter().map(|&w| (w as f64).powi(2)).sum::<f64>().sqrt();
    assert!(err < 1e-4, "latents relative L2 error {err:.2e}");
    let text = png_text(&png);
    let parameters = &text.iter().find(|(k, _)| k == "parameters").unwrap().1;
    assert!(parameters.contains("Denoising strength: 0.75") && parameters.contains("Size: 64x64"), "{parameters}");
}

/// A 128² tiny-model generation (for the VAE's memory plan) into `out` with `flags`, under `budget` where given.
fn gen(out: &std::path::Path, budget: Option<&str>, flags: &[&str]) -> Output {
    let model = fixture("tiny-sdxl");
    let mut command = Command::new(env!("CARGO_BIN_EXE_vkdiff"));
    command.args([
        "gen",
        "--model",
        &model,
        "--prompt",
        "a mushroom",
        "--steps",
        "2",
        "--width",
        "128",
        "--height",
        "128",
    ]);
    command.args(["--out", out.to_str().unwrap()]).args(flags);
    match budget {
        Some(budget) => command.env("VKDIFF_MEMORY_BUDGET", budget),
        None => command.env_remove("VKDIFF_MEMORY_BUDGET"),
    };
    command.output().unwrap()
}

#[test]
fn a_decode_past_the_budget_runs_in_tiles_and_one_that_must_be_whole_fails_first() {
    let dir = scratch("vae-budget");
    // The tiny model's weights take about 10 MiB, its 128² decode about 20 MiB whole, 5 in
    // 64-px tiles (the VAE's sample_size, diffusers' default tile).
    let tiled = dir.join("tiled.png");
    let result = gen(&tiled, Some("16M"), &[]);
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(result.status.success(), "{stderr}");
    assert!(stderr.contains("VAE: 128×128 decodes in 64-px tiles"), "{stderr}");
    let text = png_text(&tiled);
    assert!(text.iter().any(|(k, v)| k == "vae_tile" && v == "64"), "{text:?}");
    // The same tiles asked for by hand, without a budget: the same file.
    let by_hand = dir.join("by-hand.png");
    let result = gen(&by_hand, None, &["--vae-tiling", "on"]);
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    assert_eq!(std::fs::read(&tiled).unwrap(), std::fs::read(&by_hand).unwrap());
    // Without a budget the decode is whole, and no tile is recorded.
    let whole = dir.join("whole.png");
    assert!(gen(&whole, None, &[]).status.success());
    assert!(!png_text(&whole).iter().any(|(k, _)| k == "vae_tile"));
    assert_ne!(std::fs::read(&whole).unwrap(), std::fs::read(&tiled).unwrap());
    // A whole decode that cannot fit fails before the first step, writing nothing.
    let refused = dir.join("refused.png");
    let result = gen(&refused, Some("16M"), &["--vae-tiling", "off"]);
    let stderr = String::from_utf8_lossy(&result.stderr);
    let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
    assert!(!result.status.success() && errors.len() == 1, "{stderr}");
    assert!(
        errors[0].starts_with("error: --vae-tiling off: the VAE decode of 1×128×128 needs")
            && errors[0].contains("VKDIFF_MEMORY_BUDGET")
            && errors[0].contains("auto decodes in tiles"),
        "{stderr}"
    );
    assert!(!stderr.contains("denoising"), "refused before denoising: {stderr}");
    assert!(!refused.exists());
    // A tile that breaks diffusers' geometry is refused by name.
    let result = gen(&refused, None, &["--vae-tiling", "40"]);
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(stderr.contains("--vae-tiling 40: a VAE tile must be a positive multiple of 32 pixels"), "{stderr}");
}

/// The Vulkan version vkdiff runs at is the one asked for: 1.3, or 1.2 under
/// `VKDIFF_VULKAN_API=1.2` (the CI pass that runs these tests on the 1.2 paths), for the instance
/// and for every device.
#[test]
fn the_instance_and_devices_run_the_vulkan_version_asked_for() {
    let asked = std::env::var("VKDIFF_VULKAN_API").ok().filter(|v| !v.is_empty()).unwrap_or_else(|| "1.3".into());
    let out = vkdiff(&["devices", "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let devices: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for d in devices.as_array().unwrap() {
        assert_eq!(d["instance_vulkan"].as_str(), Some(asked.as_str()), "{d}");
        let version = d["vulkan"].as_str().unwrap();
        assert!(version.starts_with(&format!("{asked}.")), "device {} runs Vulkan {version}, {asked} asked", d["name"]);
    }
}
