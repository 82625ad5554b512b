//! The PNG text vkdiff writes, read by the rules of ComfyUI's frontend (ComfyUI_frontend
//! `src/scripts/metadata/png.ts` and `importA1111` in `src/scripts/pnginfo.ts`, 2026): a file
//! dropped on ComfyUI must load, and the graph it builds must carry our settings.

use regex::Regex;
use std::collections::HashMap;
use std::path::PathBuf;
use vkdiff_pipeline::files::png_bytes;
use vkdiff_pipeline::images::ControlDepth;
use vkdiff_pipeline::{
    ControlNetSettings, GenSettings, LoraSetting, ModelSettings, RgbImage, Sampling, ScheduleOptions, TextToImage,
};
use vkdiff_render::control::ControlKind;
use vkdiff_runtime::Dtype;

/// ComfyUI's KSampler sampler names (comfy/samplers.py, KSAMPLER_NAMES and the extra ones).
const COMFY_SAMPLERS: [&str; 12] = [
    "euler",
    "euler_cfg_pp",
    "euler_ancestral",
    "heun",
    "dpm_2",
    "dpm_2_ancestral",
    "lms",
    "dpmpp_2m",
    "dpmpp_sde",
    "ddim",
    "uni_pc",
    "lcm",
];

/// A text chunk as `getFromPngBuffer` sees it.
struct Chunk {
    kind: String,
    keyword: String,
    text: String,
    /// iTXt's compression flag; the frontend does not inflate, so it must be 0.
    compressed: bool,
}

fn text_chunks(png: &[u8]) -> Vec<Chunk> {
    assert_eq!(&png[..4], b"\x89PNG");
    let mut chunks = Vec::new();
    let mut at = 8;
    while at < png.len() {
        let len = u32::from_be_bytes(png[at..at + 4].try_into().unwrap()) as usize;
        let kind = String::from_utf8_lossy(&png[at + 4..at + 8]).into_owned();
        let data = &png[at + 8..at + 8 + len];
        if kind == "tEXt" || kind == "iTXt" {
            let nul = data.iter().position(|&b| b == 0).unwrap();
            let keyword = String::from_utf8_lossy(&data[..nul]).into_owned();
            let mut start = nul + 1;
            let mut compressed = false;
            if kind == "iTXt" {
                compressed = data[start] != 0;
                start += 2;
                for _ in 0..2 {
                    start += data[start..].iter().position(|&b| b == 0).unwrap() + 1;
                }
            }
            // The frontend decodes both kinds as UTF-8.
            let text = String::from_utf8_lossy(&data[start..]).into_owned();
            chunks.push(Chunk { kind, keyword, text, compressed });
        }
        at += 12 + len;
    }
    chunks
}

/// What ComfyUI's A1111 import sets in the graph it builds.
#[derive(Debug, Default)]
struct Imported {
    positive: String,
    negative: String,
    options: HashMap<String, String>,
    loras: Vec<(String, f64)>,
    sampler_name: Option<String>,
    scheduler: String,
}

/// `importA1111`'s parsing; `None` where it would build nothing.
fn import_a1111(parameters: &str) -> Option<Imported> {
    let p = parameters.rfind("\nSteps:")?;
    let line = parameters[p..].split('\n').nth(1)?;
    let pair = Regex::new(r#"\s*([^:]+:\s*([^"\{].*?|".*?"|\{.*?\}))\s*(,|$)"#).unwrap();
    let mut options = HashMap::new();
    for m in pair.find_iter(line) {
        let parts: Vec<&str> = m.as_str().split(':').collect();
        let value = parts[1].strip_suffix(',').unwrap_or(parts[1]);
        options.insert(parts[0].trim().to_lowercase(), value.trim().to_string());
    }
    let p2 = parameters[..p].rfind("\nNegative prompt:")?;
    let mut imported = Imported { negative: parameters[p2 + 18..p].trim().to_string(), options, ..Default::default() };
    let lora = Regex::new(r"<lora:([^:]+:[^>]+)>").unwrap();
    let positive = parameters[..p2].trim();
    for c in lora.captures_iter(positive) {
        let (name, weight) = c[1].split_once(':').unwrap();
        imported.loras.push((name.to_string(), weight.parse().unwrap()));
    }
    imported.positive = lora.replace_all(positive, "").into_owned();
    let mut name = imported.options["sampler"].to_lowercase().replace("++", "pp").replace(' ', "_");
    imported.scheduler = if name.contains("karras") {
        name = name.replace("karras", "").trim_end_matches('_').to_string();
        "karras".into()
    } else {
        "normal".into()
    };
    imported.sampler_name =
        COMFY_SAMPLERS.iter().find(|s| **s == name || format!("sample_{name}") == **s).map(|s| s.to_string());
    Some(imported)
}

fn settings(prompt: &str, negative: Option<&str>, sampler: &str, karras: bool) -> GenSettings {
    GenSettings {
        models: ModelSettings {
            model: "/models/stable-diffusion-xl-base-1.0".into(),
            vae: None,
            unet: None,
            precision: Dtype::F16,
            controlnets: vec![ControlNetSettings {
                model: "/models/controlnet-depth-sdxl-1.0".into(),
                controls: vec![ControlKind::Depth],
                depth_mode: ControlDepth::Inverse,
                scale: 0.5,
                start: 0.0,
                end: 0.8,
            }],
            ip_adapter: None,
            loras: vec![
                LoraSetting { path: "/loras/mushroom_style.safetensors".into(), strength: 0.7 },
                LoraSetting { path: "/loras/macro, detail.safetensors".into(), strength: 1.0 },
            ],
            vae_tiling: Default::default(),
        },
        job: TextToImage {
            prompt: prompt.into(),
            negative_prompt: negative.map(String::from),
            seed: 1234567,
            sampling: Sampling {
                steps: 30,
                guidance_scale: 5.5,
                sampler: sampler.parse().unwrap(),
                schedule: ScheduleOptions { karras, ..Default::default() },
                width: 1000,
                height: 768,
                size_conditioning: Default::default(),
                strength: None,
                prompt_syntax: Default::default(),
            },
        },
        depth: Some(PathBuf::from("scene/depth.exr")),
        control_images: Vec::new(),
        ip_images: vec![],
        init_image: None,
    }
}

fn written(settings: &GenSettings) -> Vec<u8> {
    png_bytes(&RgbImage { width: 2, height: 2, pixels: vec![7; 12] }, &settings.png_text()).unwrap()
}

#[test]
fn comfyui_imports_the_parameters_with_our_settings() {
    let prompt = "oyster mushrooms on a log, 蘑菇, champignon sur l'écorce";
    let png = written(&settings(prompt, Some("blurry, (low quality)"), "dpmpp_2m", true));
    let chunks = text_chunks(&png);
    for c in &chunks {
        assert!(
            c.keyword != "prompt" && c.keyword != "workflow",
            "ComfyUI parses a `{}` chunk as its graph JSON",
            c.keyword
        );
        assert!(!c.compressed, "`{}`: ComfyUI does not inflate compressed iTXt", c.keyword);
        let ascii = c.keyword.is_ascii() && c.text.is_ascii();
        assert_eq!(c.kind, if ascii { "tEXt" } else { "iTXt" }, "`{}`", c.keyword);
    }
    let parameters = &chunks.iter().find(|c| c.keyword == "parameters").expect("a parameters chunk").text;
    let got = import_a1111(parameters).unwrap_or_else(|| panic!("ComfyUI would import nothing from {parameters:?}"));
    assert_eq!(got.positive.trim(), prompt);
    assert_eq!(got.negative, "blurry, (low quality)");
    assert_eq!(got.loras, vec![("mushroom_style".to_string(), 0.7), ("macro, detail".to_string(), 1.0)]);
    assert_eq!((got.sampler_name.as_deref(), got.scheduler.as_str()), (Some("dpmpp_2m"), "karras"));
    let o = &got.options;
    assert_eq!(
        (o["steps"].as_str(), o["cfg scale"].as_str(), o["seed"].as_str(), o["size"].as_str()),
        ("30", "5.5", "1234567", "1000x768")
    );
    assert_eq!(o["model"], "stable-diffusion-xl-base-1.0", "ComfyUI matches ckpt_name by this prefix");
    // The same text reaches readers that follow the PNG specification (PIL, A1111).
    let decoded = png::Decoder::new(std::io::Cursor::new(&png)).read_info().unwrap();
    let info = decoded.info();
    let spec: Vec<String> = info
        .uncompressed_latin1_text
        .iter()
        .map(|t| t.text.clone())
        .chain(info.utf8_text.iter().map(|t| t.get_text().unwrap()))
        .collect();
    assert!(spec.contains(parameters) && spec.len() == chunks.len());
}

#[test]
fn a_missing_negative_prompt_still_imports_and_every_sampler_keeps_its_a1111_name() {
    for (sampler, a1111, comfy) in [
        ("euler", "Euler", Some("euler")),
        ("ddim", "DDIM", Some("ddim")),
        ("euler_a", "Euler a", None),
        ("lcm", "LCM", Some("lcm")),
        // Forge's name; ComfyUI's KSampler has no TCD and keeps its default.
        ("tcd", "TCD", None),
    ] {
        let png = written(&settings("a forest floor", None, sampler, false));
        let chunks = text_chunks(&png);
        let parameters = &chunks.iter().find(|c| c.keyword == "parameters").unwrap().text;
        let got =
            import_a1111(parameters).unwrap_or_else(|| panic!("ComfyUI would import nothing from {parameters:?}"));
        assert_eq!((got.positive.trim(), got.negative.as_str()), ("a forest floor", ""));
        assert_eq!(got.options["sampler"], a1111);
        // ComfyUI maps A1111's "Euler a" to no sampler of its own and keeps its default.
        assert_eq!((got.sampler_name.as_deref(), got.scheduler.as_str()), (comfy, "normal"));
        assert!(chunks.iter().all(|c| c.kind == "tEXt"), "ASCII text goes in tEXt");
    }
}
