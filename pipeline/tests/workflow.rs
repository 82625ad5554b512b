//! The paper's workflow against diffusers on the tiny SDXL (tools/make_workflow_fixtures.py):
//! `StableDiffusionXLControlNetPipeline`, `load_ip_adapter` and `load_lora_weights`, each alone
//! and all together, in f32 and f16. One model serves every case: LoRA sets are switched by
//! restoring and merging in place, never by reloading.

mod common;

use common::{ctx, job, psnr, relative_l2};
use serde_json::Value;
use std::collections::HashMap;
use vkdiff_formats::SafeTensors;
use vkdiff_lora::LoraFile;
use vkdiff_networks::{ClipVisionModelWithProjection, ControlNetModel, IpAdapter};
use vkdiff_pipeline::images::{read_image, ClipPreprocess};
use vkdiff_pipeline::{ControlGuide, ControlNetUse, Guides, ImageGuide, IpScale, Sdxl};
use vkdiff_runtime::Dtype;
use vkdiff_testkit::fixture;

/// Every model a case may name, loaded once for the run precision.
struct Guidance {
    controlnets: HashMap<String, ControlNetModel>,
    adapters: HashMap<String, IpAdapter>,
    encoder: ClipVisionModelWithProjection,
    preprocess: ClipPreprocess,
    loras: HashMap<String, LoraFile>,
}

impl Guidance {
    fn load(sdxl: &Sdxl, dtype: Dtype) -> Guidance {
        let ctx = ctx();
        let controlnets = ["controlnet", "controlnet-small"]
            .map(|n| {
                (
                    n.to_string(),
                    ControlNetModel::load(&ctx, &fixture("workflow").join(n), sdxl.unet_config(), dtype).unwrap(),
                )
            })
            .into();
        let adapters = ["ip-adapter_tiny.safetensors", "ip-adapter-plus_tiny.safetensors"]
            .map(|n| (n.to_string(), IpAdapter::load(&ctx, &fixture("workflow").join(n), sdxl.unet(), dtype).unwrap()))
            .into();
        let encoder =
            ClipVisionModelWithProjection::load_folder(&ctx, &fixture("workflow").join("image_encoder"), dtype)
                .unwrap();
        let preprocess = ClipPreprocess::square(encoder.config().image_size);
        let loras = ["lora-kohya-ldm.safetensors", "lora-kohya-diffusers.safetensors", "lora-peft.safetensors"]
            .map(|n| (n.to_string(), LoraFile::open(&fixture("workflow").join(n)).unwrap()))
            .into();
        Guidance { controlnets, adapters, encoder, preprocess, loras }
    }
}

/// Runs every recorded case; latents within `tol` (relative L2), images above `min_psnr`.
fn check(dtype: Dtype, tol: f64, min_psnr: f64) {
    let json: Value =
        serde_json::from_str(&std::fs::read_to_string(fixture("workflow").join("records.json")).unwrap()).unwrap();
    let records = SafeTensors::open(&fixture("workflow").join("records.safetensors")).unwrap();
    let mut sdxl = Sdxl::load(&ctx(), &fixture("workflow").join("../pipeline/tiny-sdxl"), dtype, &mut |_| {}).unwrap();
    let g = Guidance::load(&sdxl, dtype);
    let cases = json["cases"].as_array().unwrap();
    assert!(cases.len() >= 11, "fixture has {} cases", cases.len());
    for case in cases {
        let name = case["name"].as_str().unwrap();
        let loras: Vec<(&LoraFile, f32)> = case["loras"]
            .as_array()
            .unwrap()
            .iter()
            .map(|l| (&g.loras[l["file"].as_str().unwrap()], l["strength"].as_f64().unwrap() as f32))
            .collect();
        sdxl.set_loras(&loras).unwrap();
        let control_image;
        let control = match &case["control"] {
            Value::Null => None,
            c => {
                control_image = read_image(&fixture("workflow").join(c["image"].as_str().unwrap())).unwrap();
                let net = &g.controlnets[c["model"].as_str().unwrap()];
                Some(ControlGuide {
                    use_: ControlNetUse {
                        net,
                        control_types: &[],
                        scale: c["scale"].as_f64().unwrap() as f32,
                        start: c["start"].as_f64().unwrap(),
                        end: c["end"].as_f64().unwrap(),
                    },
                    images: vec![&control_image],
                })
            }
        };
        let (style_images, ip_scale);
        let image = match &case["ip"] {
            Value::Null => None,
            ip => {
                style_images = ip["images"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|p| read_image(&fixture("workflow").join(p.as_str().unwrap())).unwrap())
                    .collect::<Vec<_>>();
                let adapter = &g.adapters[ip["adapter"].as_str().unwrap()];
                ip_scale = IpScale::All(ip["scale"].as_f64().unwrap() as f32);
                Some(ImageGuide {
                    adapter,
                    encoder: &g.encoder,
                    preprocess: &g.preprocess,
                    images: &style_images,
                    scale: &ip_scale,
                })
            }
        };
        let out = sdxl
            .text_to_image(
                &job(case),
                &Guides { control: control.into_iter().collect(), image, ..Default::default() },
                &mut |_, _| {},
            )
            .unwrap();
        let (_, latents) = records.values(case["tensors"]["latents"].as_str().unwrap()).unwrap();
        let rel = relative_l2(&out.latents, &latents);
        let (_, image) = records.values(case["tensors"]["image_u8"].as_str().unwrap()).unwrap();
        let p = psnr(&out.image.pixels, &image);
        eprintln!("{dtype:?} {name}: latents rel L2 {rel:.2e}, image PSNR {p:.1} dB");
        assert!(rel <= tol, "{dtype:?} case {name}: latents relative L2 error {rel:.2e} > {tol:.0e}");
        assert!(p >= min_psnr, "{dtype:?} case {name}: image PSNR {p:.1} dB < {min_psnr} dB");
    }
}

#[test]
fn the_workflow_matches_diffusers_in_f32() {
    check(Dtype::F32, 1e-4, 50.0);
}

#[test]
fn the_workflow_matches_diffusers_in_f16() {
    check(Dtype::F16, 2e-2, 30.0);
}
