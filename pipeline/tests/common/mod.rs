//! What the generation tests share: the device, a recorded case as a job, the error measure.

use serde_json::Value;
use std::sync::OnceLock;
use vkdiff_formats::SafeTensors;
use vkdiff_networks::ControlNetModel;
use vkdiff_pipeline::images::read_image;
use vkdiff_pipeline::{
    ControlGuide, ControlNetUse, Generated, Guides, ImageGuide, PromptSyntax, RgbImage, Sampling, ScheduleOptions,
    Sdxl, SizeConditioning, TextToImage,
};
use vkdiff_runtime::{Context, Dtype};
use vkdiff_testkit::fixture;

pub fn ctx() -> Context {
    static CTX: OnceLock<Context> = OnceLock::new();
    CTX.get_or_init(|| {
        Context::new(&Default::default(), vkdiff_testkit::settings()).unwrap_or_else(|e| {
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
        timesteps: case["custom_timesteps"].as_array().map(|t| t.iter().map(|t| t.as_u64().unwrap() as u32).collect()),
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

/// A recorded case's ControlNet (of tests/fixtures/workflow) with its image and settings, and its
/// init image (in `init_dir` under tests/fixtures), loaded for `sdxl`.
#[allow(dead_code)] // not every test binary runs whole cases
pub struct CaseInputs {
    control: Option<(ControlNetModel, RgbImage, f32, f64, f64)>,
    init: Option<RgbImage>,
}

#[allow(dead_code)]
impl CaseInputs {
    pub fn load(sdxl: &Sdxl, case: &Value, init_dir: &str, dtype: Dtype) -> CaseInputs {
        let workflow = |key: &Value| fixture(&format!("workflow/{}", key.as_str().unwrap()));
        let control = match &case["control"] {
            Value::Null => None,
            c => Some((
                ControlNetModel::load(&ctx(), &workflow(&c["model"]), sdxl.unet_config(), dtype).unwrap(),
                read_image(&workflow(&c["image"])).unwrap(),
                c["scale"].as_f64().unwrap() as f32,
                c["start"].as_f64().unwrap(),
                c["end"].as_f64().unwrap(),
            )),
        };
        let init = case["init"].as_str().map(|f| read_image(&fixture(&format!("{init_dir}/{f}"))).unwrap());
        CaseInputs { control, init }
    }

    /// The case's guides, with the IP-Adapter's `image` guide where it has one.
    pub fn guides<'a>(&'a self, image: Option<ImageGuide<'a>>) -> Guides<'a> {
        let control = self.control.as_ref().map(|(net, image, scale, start, end)| ControlGuide {
            use_: ControlNetUse { net, control_types: &[], scale: *scale, start: *start, end: *end },
            images: vec![image],
        });
        Guides { control: control.into_iter().collect(), image, init: self.init.as_ref(), ..Default::default() }
    }
}

/// A generation's latents within `tol` (relative L2) of the case's recorded ones, and its 8-bit
/// image at `min_psnr` dB or better against the recorded image; both printed.
#[allow(dead_code)] // not every test binary runs whole cases
pub fn assert_case_output(
    out: &Generated,
    case: &Value,
    records: &SafeTensors,
    dtype: Dtype,
    (tol, min_psnr): (f64, f64),
) {
    let name = case["name"].as_str().unwrap();
    let (_, latents) = records.values(case["tensors"]["latents"].as_str().unwrap()).unwrap();
    let (_, pixels) = records.values(case["tensors"]["image_u8"].as_str().unwrap()).unwrap();
    let (rel, p) = (relative_l2(&out.latents, &latents), psnr(&out.image.pixels, &pixels));
    eprintln!("{dtype:?} {name}: latents rel L2 {rel:.2e}, image PSNR {p:.1} dB");
    assert!(rel <= tol, "{dtype:?} case {name}: latents relative L2 error {rel:.2e} > {tol:.0e}");
    assert!(p >= min_psnr, "{dtype:?} case {name}: image PSNR {p:.1} dB < {min_psnr} dB");
}
