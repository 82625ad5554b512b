//! `Sdxl::text_to_image` against diffusers' StableDiffusionXLPipeline on the tiny SDXL
//! (tools/make_pipeline_fixtures.py): final latents and 8-bit images, every sampler, with and
//! without guidance and negative prompts, in f32 and f16, from the folder and the single file.

mod common;

use common::{ctx, job, relative_l2};
use serde_json::Value;
use vkdiff_formats::SafeTensors;
use vkdiff_pipeline::{Guides, Sdxl, Swaps};
use vkdiff_runtime::Dtype;
use vkdiff_testkit::fixture;

fn cases() -> Vec<Value> {
    let json: Value =
        serde_json::from_str(&std::fs::read_to_string(fixture("pipeline").join("records.json")).unwrap()).unwrap();
    json["gen"].as_array().unwrap().clone()
}

/// PSNR in dB of 8-bit pixels against diffusers' [0, 1] CHW image rounded the way it saves PNGs.
fn psnr(pixels: &[u8], chw: &[f32], [c, h, w]: [usize; 3]) -> f64 {
    let mut mse = 0.0;
    for y in 0..h {
        for x in 0..w {
            for ch in 0..c {
                let want = (chw[(ch * h + y) * w + x] * 255.0).round() as f64;
                mse += (pixels[(y * w + x) * c + ch] as f64 - want).powi(2);
            }
        }
    }
    mse /= (c * h * w) as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (255.0f64 * 255.0 / mse).log10()
    }
}

/// Runs every recorded case on `model` in `dtype`; latents within `tol` (relative L2), images
/// above `min_psnr`.
fn check(model: &str, dtype: Dtype, tol: f64, min_psnr: f64, only: Option<usize>) {
    let records = SafeTensors::open(&fixture("pipeline").join("records.safetensors")).unwrap();
    let sdxl = Sdxl::load(&ctx(), &fixture("pipeline").join(model), dtype, &mut |_| {}).unwrap();
    for (i, case) in cases().iter().enumerate().filter(|(i, _)| only.is_none_or(|o| o == *i)) {
        let name = case["name"].as_str().unwrap();
        let out = sdxl.text_to_image(&job(case), &Guides::default(), &mut |_, _| {}).unwrap();
        let (_, want) = records.values(&format!("gen.{i}.latents")).unwrap();
        let rel = relative_l2(&out.latents, &want);
        assert!(rel <= tol, "{model} {dtype:?} case {i} ({name}): latents relative L2 error {rel:.2e} > {tol:.0e}");
        let (s, image) = records.values(&format!("gen.{i}.image")).unwrap();
        let p = psnr(&out.image.pixels, &image, [s[1], s[2], s[3]]);
        assert!(p >= min_psnr, "{model} {dtype:?} case {i} ({name}): image PSNR {p:.1} dB < {min_psnr} dB");
        eprintln!("{model} {dtype:?} {name}: latents rel L2 {rel:.2e}, image PSNR {p:.1} dB");
    }
}

#[test]
fn every_sampler_matches_diffusers_in_f32() {
    check("tiny-sdxl", Dtype::F32, 1e-4, 50.0, None);
}

#[test]
fn every_sampler_matches_diffusers_in_f16() {
    check("tiny-sdxl", Dtype::F16, 2e-2, 30.0, None);
}

#[test]
fn single_file_matches_diffusers() {
    check("tiny-sdxl.safetensors", Dtype::F32, 1e-4, 50.0, Some(3));
}

/// `--vae`: another VAE in the model's place, as diffusers' `vae=` swaps it
/// (tools/make_vae_swap_fixtures.py): its own scaling factor, and its config's `force_upcast:
/// false` lets it decode in f16. Its folder, its diffusers-named file and its original-layout
/// file (each reading the config beside it) give the same images.
#[test]
fn a_swapped_vae_matches_diffusers() {
    let dir = fixture("vae_swap");
    let records = SafeTensors::open(&dir.join("records.safetensors")).unwrap();
    let json: Value = serde_json::from_str(&std::fs::read_to_string(dir.join("records.json")).unwrap()).unwrap();
    let vae = dir.join("tiny-vae");
    let runs = [
        (vae.clone(), Dtype::F32, 1e-4, 50.0),
        (vae.join("diffusion_pytorch_model.safetensors"), Dtype::F32, 1e-4, 50.0),
        (vae.join("sdxl_vae.safetensors"), Dtype::F32, 1e-4, 50.0),
        (vae.join("sdxl_vae.safetensors"), Dtype::F16, 2e-2, 30.0),
    ];
    for (path, dtype, tol, min_psnr) in runs {
        let model = fixture("pipeline").join("tiny-sdxl");
        let sdxl = Sdxl::load_with(&ctx(), &model, Swaps { vae: Some(&path), unet: None }, dtype, &mut |_| {}).unwrap();
        assert_eq!(
            sdxl.vae_dtype(),
            dtype,
            "{}: force_upcast false runs the VAE at the run's precision",
            path.display()
        );
        for case in json["cases"].as_array().unwrap() {
            let name = case["name"].as_str().unwrap();
            let out = sdxl.text_to_image(&job(case), &Guides::default(), &mut |_, _| {}).unwrap();
            let (_, want) = records.values(&format!("{name}.latents")).unwrap();
            let rel = relative_l2(&out.latents, &want);
            assert!(rel <= tol, "{} {dtype:?} {name}: latents relative L2 error {rel:.2e}", path.display());
            let (s, image) = records.values(&format!("{name}.image")).unwrap();
            let p = psnr(&out.image.pixels, &image, [s[1], s[2], s[3]]);
            assert!(p >= min_psnr, "{} {dtype:?} {name}: image PSNR {p:.1} dB < {min_psnr} dB", path.display());
        }
    }
    // Without a config beside it, a VAE file is SDXL's: forced to f32.
    let alone = vkdiff_testkit::scratch("vae-alone").join("vae.safetensors");
    std::fs::copy(vae.join("sdxl_vae.safetensors"), &alone).unwrap();
    let model = fixture("pipeline").join("tiny-sdxl");
    let sdxl =
        Sdxl::load_with(&ctx(), &model, Swaps { vae: Some(&alone), unet: None }, Dtype::F16, &mut |_| {}).unwrap();
    assert_eq!(sdxl.vae_dtype(), Dtype::F32);
}

#[test]
fn released_text_encoders_free_their_memory_and_later_prompts_fail_clearly() {
    // A private context: its live bytes are this test's alone.
    let ctx = vkdiff_runtime::Context::new(&Default::default(), vkdiff_testkit::settings()).unwrap();
    let load = || Sdxl::load(&ctx, &fixture("pipeline").join("tiny-sdxl"), Dtype::F32, &mut |_| {}).unwrap();
    let case = &cases()[1];
    let mut sdxl = load();
    let text = sdxl.encode_job(&job(case)).unwrap();
    let held = || ctx.live_bytes() + ctx.host_bytes();
    let (before, device) = (held(), ctx.live_bytes());
    let freed = sdxl.release_text_encoders();
    assert!(freed > 0 && held() == before - freed, "freed {freed} of {before} bytes");
    assert_eq!(ctx.live_bytes(), device, "the text encoders' weights are in host memory, not the device's");
    let released = sdxl.text_to_image_encoded(&job(case), &text, &Guides::default(), &mut |_, _| {}).unwrap();
    let err = sdxl.encode_job(&job(case)).unwrap_err().to_string();
    assert!(err.contains("text encoders were released"), "{err}");
    drop(sdxl);
    // The encodings made before the release give the image the whole pipeline gives.
    let whole = load().text_to_image(&job(case), &Guides::default(), &mut |_, _| {}).unwrap();
    assert_eq!(released.image.pixels, whole.image.pixels);
}
