//! The few-step recipes against diffusers on the tiny SDXL (tools/make_few_step_fixtures.py):
//! every sampler under its recipe (SDXL-Lightning, Hyper-SD, LCM, TCD, Turbo, DMD2) alone, with
//! the depth ControlNet over the few steps, and from an init image on a trailing schedule; and a
//! UNet swapped in from a file in each stored layout (diffusers' names, the original ones, a
//! torch `.bin`); and each distillation LoRA in its published layout, DMD2's merged beside the
//! workflow's two style LoRAs.

mod common;

use common::{assert_case_output, ctx, job, CaseInputs};
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::PathBuf;
use vkdiff_formats::SafeTensors;
use vkdiff_lora::LoraFile;
use vkdiff_pipeline::{SchedulerConfig, Sdxl, Swaps};
use vkdiff_runtime::Dtype;
use vkdiff_testkit::fixture;

fn cases() -> Vec<Value> {
    let records: Value =
        serde_json::from_str(&std::fs::read_to_string(fixture("few_step/records.json")).unwrap()).unwrap();
    records["cases"].as_array().unwrap().clone()
}

#[test]
fn every_recipe_schedules_the_timesteps_diffusers_runs() {
    let config = SchedulerConfig::of_model(&fixture("pipeline/tiny-sdxl")).unwrap();
    let cases = cases();
    assert!(cases.len() >= 20, "{} cases", cases.len());
    for case in &cases {
        let sampler = job(case).sampling.sampler(&config).unwrap();
        let want: Vec<f32> =
            case["diffusers_timesteps"].as_array().unwrap().iter().map(|t| t.as_f64().unwrap() as f32).collect();
        assert_eq!(sampler.timesteps(), want, "{}", case["name"]);
    }
}

/// Merges the case's LoRAs (files under tests/fixtures, with their strengths), replacing the
/// previous case's; none restores the weights.
fn merge_loras(sdxl: &mut Sdxl, case: &Value) {
    let files: Vec<(LoraFile, f32)> = case["loras"]
        .as_array()
        .map(|l| {
            l.iter()
                .map(|l| (LoraFile::open(&fixture(l[0].as_str().unwrap())).unwrap(), l[1].as_f64().unwrap() as f32))
                .collect()
        })
        .unwrap_or_default();
    let refs: Vec<(&LoraFile, f32)> = files.iter().map(|(f, s)| (f, *s)).collect();
    sdxl.set_loras(&refs).unwrap();
}

/// Every case on the tiny SDXL in `dtype`, the models loaded once per UNet file: latents within
/// `tol` (relative L2) of diffusers', images at `min_psnr` or better.
fn check(dtype: Dtype, tol: f64, min_psnr: f64) {
    let records = SafeTensors::open(&fixture("few_step/records.safetensors")).unwrap();
    let mut by_unet: BTreeMap<Option<String>, Vec<Value>> = BTreeMap::new();
    for case in cases() {
        by_unet.entry(case["unet"].as_str().map(String::from)).or_default().push(case);
    }
    for (unet, cases) in by_unet {
        let unet: Option<PathBuf> = unet.map(|f| fixture(&format!("few_step/{f}")));
        let swaps = Swaps { vae: None, unet: unet.as_deref() };
        let mut sdxl = Sdxl::load_with(&ctx(), &fixture("pipeline/tiny-sdxl"), swaps, dtype, &mut |_| {}).unwrap();
        for case in cases {
            merge_loras(&mut sdxl, &case);
            let inputs = CaseInputs::load(&sdxl, &case, "compat", dtype);
            let out = sdxl.text_to_image(&job(&case), &inputs.guides(None), &mut |_, _| {}).unwrap();
            assert_case_output(&out, &case, &records, dtype, (tol, min_psnr));
        }
    }
}

#[test]
fn few_step_recipes_and_swapped_unets_match_diffusers_in_f32() {
    check(Dtype::F32, 1e-5, 50.0);
}

#[test]
fn few_step_recipes_and_swapped_unets_match_diffusers_in_f16() {
    check(Dtype::F16, 2e-2, 30.0);
}
