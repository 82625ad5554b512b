//! What users bring from diffusers, against diffusers on the tiny SDXL
//! (tools/make_compat_fixtures.py): IP-Adapter scales per block (`set_ip_adapter_scale` with a
//! dict, InstantStyle's style-only adapter among them), SDXL's size micro-conditioning, and
//! img2img (`StableDiffusionXLImg2ImgPipeline` with every sampler, and its ControlNet twin with an
//! init image of another size), and weighted, long prompts as diffusers' long-prompt-weighting
//! SDXL pipeline reads them.

mod common;

use common::{assert_case_output, ctx, job, relative_l2, CaseInputs};
use serde_json::Value;
use vkdiff_formats::SafeTensors;
use vkdiff_networks::{ClipVisionModelWithProjection, IpAdapter};
use vkdiff_pipeline::images::{read_image, ClipPreprocess};
use vkdiff_pipeline::{parse_attention, ImageGuide, IpScale, Sdxl};
use vkdiff_runtime::Dtype;
use vkdiff_testkit::fixture;

fn records() -> Value {
    serde_json::from_str(&std::fs::read_to_string(fixture("compat/records.json")).unwrap()).unwrap()
}

fn cases() -> Vec<Value> {
    records()["cases"].as_array().unwrap().clone()
}

#[test]
fn the_emphasis_parser_reads_prompts_as_a1111_does() {
    let corpus = records()["parse_prompt_attention"].as_object().unwrap().clone();
    assert!(corpus.len() >= 10);
    for (text, want) in corpus {
        let got = parse_attention(&text).unwrap();
        let want: Vec<(String, f64)> = want
            .as_array()
            .unwrap()
            .iter()
            .map(|r| (r[0].as_str().unwrap().to_string(), r[1].as_f64().unwrap()))
            .collect();
        assert_eq!(got.len(), want.len(), "{text:?}: {got:?} vs {want:?}");
        for ((t, w), (wt, ww)) in got.iter().zip(&want) {
            assert!(t == wt && (w - ww).abs() <= 1e-12 * ww.abs(), "{text:?}: {got:?} vs {want:?}");
        }
    }
}

#[test]
fn weighted_long_prompts_encode_as_diffusers_long_prompt_pipeline() {
    let sdxl = Sdxl::load(&ctx(), &fixture("pipeline/tiny-sdxl"), Dtype::F32, &mut |_| {}).unwrap();
    let records = SafeTensors::open(&fixture("compat/records.safetensors")).unwrap();
    for case in cases().iter().filter(|c| c["prompt_syntax"] == "weighted") {
        let text = sdxl
            .encode_weighted_prompt(case["prompt"].as_str().unwrap(), case["negative_prompt"].as_str(), true)
            .unwrap();
        assert_eq!(text.tokens as u64, case["tokens"].as_u64().unwrap(), "{}", case["name"]);
        for (got, key) in [(&text.context, "context"), (&text.pooled, "pooled")] {
            let (_, want) = records.values(case["tensors"][key].as_str().unwrap()).unwrap();
            let rel = relative_l2(got, &want);
            assert!(rel < 1e-5, "{} {key}: relative L2 error {rel:.2e}", case["name"]);
        }
    }
}

fn ip_scale(case: &Value) -> IpScale {
    let flags: Vec<String> =
        case["ip_scale_flags"].as_array().unwrap().iter().map(|f| f.as_str().unwrap().to_string()).collect();
    IpScale::parse(&flags, None).unwrap()
}

#[test]
fn ip_scale_flags_give_every_layer_the_scale_diffusers_sets() {
    let sdxl = Sdxl::load(&ctx(), &fixture("pipeline/tiny-sdxl"), Dtype::F32, &mut |_| {}).unwrap();
    let crosses = sdxl.unet().cross_attentions();
    for case in cases().iter().filter(|c| c["ip"].is_object()) {
        let got = ip_scale(case).per_layer(crosses).unwrap();
        let want = case["ip_scales"].as_object().unwrap();
        assert_eq!(want.len(), crosses.len(), "{}", case["name"]);
        for (cross, got) in crosses.iter().zip(got) {
            let want = want[&cross.name].as_f64().unwrap() as f32;
            assert_eq!(got, want, "{} {}", case["name"], cross.name);
        }
    }
}

fn check(dtype: Dtype, tol: f64, min_psnr: f64) {
    let ctx = ctx();
    let records = SafeTensors::open(&fixture("compat/records.safetensors")).unwrap();
    let sdxl = Sdxl::load(&ctx, &fixture("pipeline/tiny-sdxl"), dtype, &mut |_| {}).unwrap();
    let encoder = ClipVisionModelWithProjection::load_folder(&ctx, &fixture("workflow/image_encoder"), dtype).unwrap();
    let preprocess = ClipPreprocess::square(encoder.config().image_size);
    for case in cases() {
        let (adapter, images, scale);
        let image = match &case["ip"] {
            Value::Null => None,
            ip => {
                adapter = IpAdapter::load(
                    &ctx,
                    &fixture(&format!("workflow/{}", ip["adapter"].as_str().unwrap())),
                    sdxl.unet(),
                    dtype,
                )
                .unwrap();
                images = ip["images"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|p| read_image(&fixture(&format!("workflow/{}", p.as_str().unwrap()))).unwrap())
                    .collect::<Vec<_>>();
                scale = ip_scale(&case);
                Some(ImageGuide {
                    adapter: &adapter,
                    encoder: &encoder,
                    preprocess: &preprocess,
                    images: &images,
                    scale: &scale,
                })
            }
        };
        let inputs = CaseInputs::load(&sdxl, &case, "compat", dtype);
        let guides = inputs.guides(image);
        let out = sdxl.text_to_image(&job(&case), &guides, &mut |_, _| {}).unwrap();
        assert_case_output(&out, &case, &records, dtype, (tol, min_psnr));
    }
}

#[test]
fn ip_block_scales_size_conditioning_and_img2img_match_diffusers_in_f32() {
    check(Dtype::F32, 1e-4, 50.0);
}

#[test]
fn ip_block_scales_size_conditioning_and_img2img_match_diffusers_in_f16() {
    check(Dtype::F16, 2e-2, 30.0);
}
