//! Several ControlNets at once against diffusers' `MultiControlNetModel` on the tiny SDXL
//! (tools/make_multi_controlnet_fixtures.py): the depth ControlNet and the small one, each with its
//! own image, scale and window of steps, their residuals summed; f32 latents within 1e-5.

mod common;

use common::{ctx, job, relative_l2};
use serde_json::Value;
use vkdiff_formats::SafeTensors;
use vkdiff_networks::ControlNetModel;
use vkdiff_pipeline::images::read_image;
use vkdiff_pipeline::{ControlGuide, ControlNetUse, Guides, Sdxl};
use vkdiff_runtime::Dtype;
use vkdiff_testkit::fixture;

#[test]
fn two_controlnets_sum_as_diffusers_sums_them_in_f32() {
    let dir = fixture("workflow");
    let json: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("multi_controlnet.json")).unwrap()).unwrap();
    let records = SafeTensors::open(&dir.join("multi_controlnet.safetensors")).unwrap();
    let sdxl = Sdxl::load(&ctx(), &dir.join("../pipeline/tiny-sdxl"), Dtype::F32, &mut |_| {}).unwrap();
    let load = |name: &str| ControlNetModel::load(&ctx(), &dir.join(name), sdxl.unet_config(), Dtype::F32).unwrap();
    let nets = [("controlnet", load("controlnet")), ("controlnet-small", load("controlnet-small"))];
    let cases = json["cases"].as_array().unwrap();
    assert_eq!(cases.len(), 2);
    for case in cases {
        let name = case["name"].as_str().unwrap();
        let controls = case["controls"].as_array().unwrap();
        let images: Vec<_> =
            controls.iter().map(|c| read_image(&dir.join(c["image"].as_str().unwrap())).unwrap()).collect();
        let guides: Vec<ControlGuide> = controls
            .iter()
            .zip(&images)
            .map(|(c, image)| ControlGuide {
                use_: ControlNetUse {
                    net: &nets.iter().find(|(n, _)| *n == c["model"].as_str().unwrap()).unwrap().1,
                    control_types: &[],
                    scale: c["scale"].as_f64().unwrap() as f32,
                    start: c["start"].as_f64().unwrap(),
                    end: c["end"].as_f64().unwrap(),
                },
                images: vec![image],
            })
            .collect();
        let out = sdxl.denoise(&job(case), &Guides { control: guides, ..Default::default() }, &mut |_, _| {});
        let (_, latents) = records.values(case["tensors"]["latents"].as_str().unwrap()).unwrap();
        let rel = relative_l2(&out.unwrap().latents, &latents);
        // The second net moves diffusers' latents by this much: the tolerance is far below it.
        let moved = case["second_net_moves"].as_f64().unwrap();
        eprintln!("{name}: latents rel L2 {rel:.2e} (the second net moves them {moved:.1e})");
        assert!(rel <= 1e-5 && moved > 1e3 * rel, "case {name}: latents relative L2 error {rel:.2e}");
    }
}
