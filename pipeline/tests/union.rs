//! ControlNet-Union in the denoising loop against diffusers' `StableDiffusionXLControlNetUnionPipeline`
//! on the tiny SDXL (tools/make_union_pipeline_fixtures.py): one Union model seeing two controls at
//! once (scaled inside the net, running at every step, its range cutting the controls' scales), the
//! same model seeing one, and two Union models with their own controls and ranges
//! (`MultiControlNetUnionModel`); f32 latents within 1e-5.

mod common;

use common::{ctx, job, relative_l2};
use serde_json::Value;
use vkdiff_formats::SafeTensors;
use vkdiff_networks::ControlNetModel;
use vkdiff_pipeline::images::read_image;
use vkdiff_pipeline::{ControlGuide, ControlNetUse, Guides, RgbImage, Sdxl};
use vkdiff_runtime::Dtype;
use vkdiff_testkit::fixture;

#[test]
fn union_controlnets_match_diffusers_union_pipeline_in_f32() {
    let dir = fixture("workflow");
    let json: Value = serde_json::from_str(&std::fs::read_to_string(dir.join("union_pipeline.json")).unwrap()).unwrap();
    let records = SafeTensors::open(&dir.join("union_pipeline.safetensors")).unwrap();
    let sdxl = Sdxl::load(&ctx(), &dir.join("../pipeline/tiny-sdxl"), Dtype::F32, &mut |_| {}).unwrap();
    let load = |name: &str| ControlNetModel::load(&ctx(), &dir.join(name), sdxl.unet_config(), Dtype::F32).unwrap();
    let models = ["controlnet-union", "controlnet-union-promax.safetensors"].map(|n| (n, load(n)));
    assert_eq!(models.each_ref().map(|(_, m)| m.control_types()), [Some(6), Some(8)]);
    let cases = json["cases"].as_array().unwrap();
    assert_eq!(cases.len(), 3);
    for case in cases {
        let name = case["name"].as_str().unwrap();
        let nets = case["nets"].as_array().unwrap();
        let modes: Vec<Vec<usize>> = (nets.iter())
            .map(|n| n["modes"].as_array().unwrap().iter().map(|m| m.as_u64().unwrap() as usize).collect())
            .collect();
        let images: Vec<Vec<RgbImage>> = (nets.iter())
            .map(|n| n["images"].as_array().unwrap().iter().map(|i| read_image(&dir.join(i.as_str().unwrap()))))
            .map(|images| images.map(Result::unwrap).collect())
            .collect();
        let guides: Vec<ControlGuide> = (nets.iter().zip(&modes).zip(&images))
            .map(|((n, modes), images)| ControlGuide {
                use_: ControlNetUse {
                    net: &models.iter().find(|(m, _)| *m == n["model"].as_str().unwrap()).unwrap().1,
                    control_types: modes,
                    scale: n["scale"].as_f64().unwrap() as f32,
                    start: n["start"].as_f64().unwrap(),
                    end: n["end"].as_f64().unwrap(),
                },
                images: images.iter().collect(),
            })
            .collect();
        let out = sdxl.denoise(&job(case), &Guides { control: guides, ..Default::default() }, &mut |_, _| {});
        let (_, latents) = records.values(case["tensors"]["latents"].as_str().unwrap()).unwrap();
        let rel = relative_l2(&out.unwrap().latents, &latents);
        let moved = case["last_control_moves"].as_f64();
        eprintln!("{name}: latents rel L2 {rel:.2e} (the last control moves them {moved:?})");
        assert!(rel <= 1e-5, "case {name}: latents relative L2 error {rel:.2e}");
        assert!(moved.is_none_or(|m| m > 1e3 * rel), "case {name}: the last control moves the latents too little");
    }
}
