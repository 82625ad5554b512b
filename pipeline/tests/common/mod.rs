//! What the generation tests share: the device, a recorded case as a job, the error measure.

use serde_json::Value;
use std::sync::OnceLock;
use vkdiff_pipeline::{PromptSyntax, Sampling, ScheduleOptions, SizeConditioning, TextToImage};
use vkdiff_runtime::Context;

pub fn ctx() -> Context {
    static CTX: OnceLock<Context> = OnceLock::new();
    CTX.get_or_init(|| {
        Context::new(&Default::default()).unwrap_or_else(|e| {
            panic!(
                "pipeline tests need a Vulkan device and found none usable: \
            {e}\n(on Debian: apt-get install -y mesa-vulkan-drivers libvulkan1)"
            )
        })
    })
    .clone()
}

/// A recorded case's schedule options (absent keys: the model's settings).
fn schedule(case: &Value) -> ScheduleOptions {
    ScheduleOptions {
        karras: case["karras"].as_bool().unwrap_or(false),
        spacing: case["timestep_spacing"].as_str().map(|s| s.parse().unwrap()),
        prediction: case["prediction_type"].as_str().map(|s| s.parse().unwrap()),
        timesteps: case["timesteps"].as_array().map(|t| t.iter().map(|t| t.as_u64().unwrap() as u32).collect()),
        eta: case["eta"].as_f64(),
    }
}

/// A recorded case's settings (`karras` absent means false).
pub fn job(case: &Value) -> TextToImage {
    TextToImage {
        prompt: case["prompt"].as_str().unwrap().into(),
        negative_prompt: case["negative_prompt"].as_str().map(String::from),
        seed: case["seed"].as_u64().unwrap(),
        sampling: Sampling {
            steps: case["steps"].as_u64().unwrap() as usize,
            guidance_scale: case["guidance_scale"].as_f64().unwrap() as f32,
            sampler: case["sampler"].as_str().unwrap().parse().unwrap(),
            schedule: schedule(case),
            width: case["width"].as_u64().unwrap() as usize,
            height: case["height"].as_u64().unwrap() as usize,
            size_conditioning: SizeConditioning {
                // diffusers' sizes are (height, width).
                original: pair(&case["original_size"]).map(|(h, w)| (w, h)),
                crop_top_left: pair(&case["crops_coords_top_left"]).unwrap_or((0, 0)),
                target: pair(&case["target_size"]).map(|(h, w)| (w, h)),
            },
            strength: case["strength"].as_f64(),
            prompt_syntax: if case["prompt_syntax"] == "weighted" {
                PromptSyntax::Weighted
            } else {
                PromptSyntax::Plain
            },
        },
    }
}

/// A two-number array of a case, as it stands.
fn pair(v: &Value) -> Option<(usize, usize)> {
    Some((v.get(0)?.as_u64()? as usize, v.get(1)?.as_u64()? as usize))
}

pub fn relative_l2(got: &[f32], want: &[f32]) -> f64 {
    let diff: f64 = got.iter().zip(want).map(|(&g, &w)| (g as f64 - w as f64).powi(2)).sum();
    let norm: f64 = want.iter().map(|&w| (w as f64).powi(2)).sum();
    (diff / norm).sqrt()
}

/// PSNR in dB of 8-bit pixels against the same pixels recorded as f32 (diffusers' PIL image).
#[allow(dead_code)] // not every test binary compares images
pub fn psnr(got: &[u8], want: &[f32]) -> f64 {
    let mse = got.iter().zip(want).map(|(&g, &w)| (g as f64 - w as f64).powi(2)).sum::<f64>() / want.len() as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (255.0f64 * 255.0 / mse).log10()
    }
}
