//! LoRA files as diffusers, PEFT and kohya write them (tools/make_workflow_fixtures.py,
//! tools/make_compat_fixtures.py: PEFT adapters saved under transformers 5), merged at the
//! strength the records were fused at and compared with diffusers' fuse_lora result.

use crate::common::*;
use vkdiff_lora::{LoraFile, LoraMerger, Targets};
use vkdiff_runtime::Dtype;
use vkdiff_unet::{ParamLayout, SafeTensors};

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

#[test]
fn diffusers_fixtures_match_fuse_lora() {
    check_fused("tests/fixtures/workflow", 3);
}

#[test]
fn a_peft_lora_saved_under_transformers_5_matches_fuse_lora() {
    check_fused("tests/fixtures/compat", 1);
}

/// Every LoRA of the fixture folder `dir` (`files` of them) against diffusers' fused weights.
fn check_fused(dir: &str, files: usize) {
    let dir = repo(dir);
    let json = std::fs::read_to_string(dir.join("records.json"))
        .unwrap_or_else(|e| panic!("{}: {e} (regenerate with tools/make_workflow_fixtures.py)", dir.join("records.json").display()));
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
        let summary = merger.apply(&Targets::sdxl(&nets.unet, &nets.clip_l, &nets.big_g), &[(&lora, strength)]).unwrap();
        println!("{stem}: {summary}");
        let s = &summary.loras[0];
        let modules = l["modules"].as_array().map_or(0, Vec::len);
        assert_eq!(s.unet + s.text_encoder_1 + s.text_encoder_2 + s.not_run, modules, "{stem}: every module diffusers applied is merged or not run");
        for r in l["fused_records"].as_array().unwrap() {
            let param = r["param"].as_str().unwrap();
            let (net, name) =
                [("unet.", 0), ("text_encoder.", 1), ("text_encoder_2.", 2)].iter().find_map(|(p, n)| Some((*n, param.strip_prefix(p)?))).unwrap();
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
