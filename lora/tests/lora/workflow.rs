//! LoRA files as diffusers, PEFT and kohya write them (tools/make_workflow_fixtures.py,
//! tools/make_compat_fixtures.py: PEFT adapters saved under transformers 5), merged at the
//! strength the records were fused at and compared with diffusers' fuse_lora result.

use crate::common::*;
use std::path::Path;
use vkdiff_formats::SafeTensors;
use vkdiff_lora::{LoraFile, LoraMerger, Targets};
use vkdiff_networks::ParamLayout;
use vkdiff_runtime::Dtype;

/// PyTorch layout [o, i, kh, kw] of a device tensor [o, kh, kw, i].
fn ohwi_to_oihw(x: &[f32], s: &[usize]) -> Vec<f32> {
    let (o, i, h, w) = (s[0], s[1], s[2], s[3]);
    let mut out = vec![0.0; x.len()];
    for a in 0..o {
        for c in 0..i {
            for y in 0..h {
                for z in 0..w {
                    out[((a * i + c) * h + y) * w + z] = x[((a * h + y) * w + z) * i + c];
                }
            }
        }
    }
    out
}

/// A renaming of a LoRA's keys as another tool saves them (None drops the key).
type Respell = dyn Fn(&str) -> Option<String>;

#[test]
fn diffusers_fixtures_match_fuse_lora() {
    check_fused("tests/fixtures/workflow", 3);
}

/// SDXL-Lightning's, Hyper-SD's, LCM's, TCD's and DMD2's LoRAs in their published layouts
/// (tools/make_few_step_fixtures.py).
#[test]
fn distillation_loras_match_fuse_lora() {
    check_fused("tests/fixtures/few_step", 5);
}

#[test]
fn a_peft_lora_saved_under_transformers_5_matches_fuse_lora() {
    check_fused("tests/fixtures/compat", 1);
}

/// Every LoRA of the fixture folder `dir` (`files` of them) against diffusers' fused weights.
fn check_fused(dir: &str, files: usize) {
    let dir = repo(dir);
    let json = std::fs::read_to_string(dir.join("records.json")).unwrap_or_else(|e| {
        panic!("{}: {e} (regenerate with tools/make_workflow_fixtures.py)", dir.join("records.json").display())
    });
    let meta: serde_json::Value = serde_json::from_str(&json).unwrap();
    let records = SafeTensors::open(&dir.join("records.safetensors")).unwrap();
    let loras = meta["loras"].as_object().expect("records.json has no `loras`");
    assert_eq!(loras.len(), files, "{:?}", loras.keys());
    let nets = tiny_sdxl(Dtype::F32);
    let before = nets.params().map(snapshot);
    for (stem, l) in loras {
        let lora = LoraFile::open(&dir.join(l["file"].as_str().unwrap())).unwrap();
        let strength = l["fused_strength"].as_f64().unwrap() as f32;
        let mut merger = LoraMerger::new();
        let summary =
            merger.apply(&Targets::sdxl(&nets.unet, &nets.clip_l, &nets.big_g), &[(&lora, strength)]).unwrap();
        println!("{stem}: {summary}");
        let s = &summary.loras[0];
        let modules = l["modules"].as_array().map_or(0, Vec::len);
        assert_eq!(
            s.unet + s.text_encoder_1 + s.text_encoder_2 + s.not_run,
            modules,
            "{stem}: every module diffusers applied is merged or not run"
        );
        for r in l["fused_records"].as_array().unwrap() {
            let param = r["param"].as_str().unwrap();
            let (net, name) = [("unet.", 0), ("text_encoder.", 1), ("text_encoder_2.", 2)]
                .iter()
                .find_map(|(p, n)| Some((*n, param.strip_prefix(p)?)))
                .unwrap();
            let p = nets.params()[net].get(name).unwrap_or_else(|| panic!("{stem}: no parameter `{name}`"));
            let mut got = p.tensor.download().unwrap();
            if p.layout == ParamLayout::ConvOhwi {
                got = ohwi_to_oihw(&got, &p.torch_shape);
            }
            let (_, want) = records.values(r["merged"].as_str().unwrap()).unwrap();
            let (_, base) = records.values(r["base"].as_str().unwrap()).unwrap();
            let scale = want.iter().map(|v| v.abs()).fold(0.0f32, f32::max);
            let moved = want.iter().zip(&base).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
            assert!(moved > 1e-3 * scale, "{stem} {param}: the record does not differ from the base");
            for (i, (g, w)) in got.iter().zip(&want).enumerate() {
                assert!((g - w).abs() <= 1e-5 * scale, "{stem} {param} element {i}: got {g}, diffusers {w}");
            }
        }
        merger.restore().unwrap();
        for (b, p) in before.iter().zip(nets.params()) {
            assert_restored(stem, b, p);
        }
    }
}

/// The tensors of `path` under names `rename` gives (`None` drops one), with the file's PEFT
/// metadata.
fn renamed(path: &Path, out: &Path, rename: impl Fn(&str) -> Option<String>) {
    let file = SafeTensors::open(path).unwrap();
    let tensors: Vec<(String, Vec<usize>, Vec<f32>)> = file
        .entries
        .keys()
        .filter_map(|k| Some((rename(k)?, file.values(k).unwrap().0, file.values(k).unwrap().1)))
        .collect();
    let bytes = std::fs::read(path).unwrap();
    let n = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let header: serde_json::Value = serde_json::from_slice(&bytes[8..8 + n]).unwrap();
    let meta = header["__metadata__"]["lora_adapter_metadata"].as_str().unwrap().to_string();
    write(out, &tensors, &[("lora_adapter_metadata", meta)]);
}

#[test]
fn every_layout_of_one_lora_merges_the_same_weights() {
    // The diffusers file (held to fuse_lora above) against the same factors as ComfyUI saves them
    // and as other diffusers / PEFT versions spell them.
    let dir = repo("tests/fixtures/compat");
    let source = dir.join("lora-peft-transformers5.safetensors");
    let out = scratch("layouts");
    std::fs::create_dir_all(&out).unwrap();
    let spellings: [(&str, &Respell); 4] = [
        ("UNet keys without `unet.`", &|k| Some(k.strip_prefix("unet.").unwrap_or(k).to_string())),
        ("PEFT's `base_model.model.` and adapter name", &|k| {
            let (component, rest) = k.split_once('.').unwrap();
            Some(format!(
                "{component}.base_model.model.{}",
                rest.replace(".lora_A.", ".lora_A.default.").replace(".lora_B.", ".lora_B.default.")
            ))
        }),
        ("CLIP-L with `text_model.`", &|k| {
            Some(k.replacen("text_encoder.encoder.", "text_encoder.text_model.encoder.", 1))
        }),
        ("kohya-style factor names on diffusers paths", &|k| {
            Some(k.replace(".lora_A.weight", ".lora_down.weight").replace(".lora_B.weight", ".lora_up.weight"))
        }),
    ];
    let mut files = vec![("ComfyUI's save node".to_string(), dir.join("lora-comfyui.safetensors"))];
    for (i, (what, rename)) in spellings.iter().enumerate() {
        let path = out.join(format!("{i}.safetensors"));
        renamed(&source, &path, rename);
        files.push((what.to_string(), path));
    }
    let nets = tiny_sdxl(Dtype::F32);
    let targets = Targets::sdxl(&nets.unet, &nets.clip_l, &nets.big_g);
    let merged = |path: &Path| {
        let lora = LoraFile::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let mut merger = LoraMerger::new();
        let summary = merger.apply(&targets, &[(&lora, 0.7)]).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let weights = nets.params().map(snapshot);
        merger.restore().unwrap();
        (summary.loras[0].unet, summary.loras[0].text_encoder_1, summary.loras[0].text_encoder_2, weights)
    };
    let want = merged(&source);
    assert!(want.0 > 0 && want.1 > 0 && want.2 > 0, "the fixture adapts all three networks");
    for (what, path) in files {
        let got = merged(&path);
        assert_eq!((got.0, got.1, got.2), (want.0, want.1, want.2), "{what}: modules merged per network");
        assert!(got.3 == want.3, "{what}: merged weights differ from the diffusers file's");
    }
}
