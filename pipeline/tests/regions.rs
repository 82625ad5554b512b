//! A prompt per category and a strength per region on the tiny SDXL, held to
//! tools/make_regions_fixtures.py (ComfyUI's masked conditioning and DifferentialDiffusion written
//! out with diffusers' models) over the orchard-a scene: two prompted categories and the rest,
//! feathered, with guidance and the ControlNet; strengths per category and background from the
//! render; both together under LCM without guidance; regions with the IP-Adapter. f32 latents
//! within 1e-5. And the two degenerate cases byte for byte: one region over everything is that
//! region's plain prompt, and one strength everywhere is plain img2img.

mod common;

use common::{ctx, job, relative_l2};
use serde_json::Value;
use std::collections::HashMap;
use vkdiff_formats::image::read_grey_png;
use vkdiff_formats::SafeTensors;
use vkdiff_networks::{ClipVisionModelWithProjection, ControlNetModel, IpAdapter};
use vkdiff_pipeline::images::masks::{region_masks, relative_strengths};
use vkdiff_pipeline::images::{read_image, ClipPreprocess};
use vkdiff_pipeline::{
    Conditioning, ControlNetUse, Denoiser, Guides, ImageGuide, InitLatents, IpAdapterUse, IpScale, ItemInputs, Regions,
    RgbImage, Sdxl, TextToImage,
};
use vkdiff_runtime::Dtype;
use vkdiff_testkit::fixture;

/// Each pixel's category and the categories' ids by name, from the scene folder.
fn scene() -> (Vec<u32>, usize, usize, HashMap<String, u32>) {
    let dir = fixture("scenes/folders/orchard-a");
    let meta: Value = serde_json::from_slice(&std::fs::read(dir.join("categories.json")).unwrap()).unwrap();
    let of: HashMap<u16, u32> = (meta["instances"].as_object().unwrap().iter())
        .map(|(k, v)| (k.parse().unwrap(), v.as_u64().unwrap() as u32))
        .collect();
    let ids = read_grey_png(&dir.join("instances.png")).unwrap();
    let categories = ids.values.iter().map(|i| of.get(i).copied().unwrap_or(0)).collect();
    let names = (meta["categories"].as_array().unwrap().iter())
        .map(|c| (c["name"].as_str().unwrap().to_string(), c["id"].as_u64().unwrap() as u32))
        .collect();
    (categories, ids.width, ids.height, names)
}

struct Scene {
    categories: Vec<u32>,
    width: usize,
    height: usize,
    names: HashMap<String, u32>,
}

impl Scene {
    fn latent(&self) -> (usize, usize) {
        (self.width / 8, self.height / 8)
    }

    /// The region prompts' conditioning and masks.
    fn regions(&self, sdxl: &Sdxl, case: &Value) -> Option<(Vec<Conditioning>, Vec<Vec<f32>>)> {
        let prompts = case["region_prompts"].as_object()?;
        let prompted: Vec<u32> = prompts.keys().map(|k| self.names[k]).collect();
        let feather = case["feather"].as_u64().unwrap() as usize;
        let masks = region_masks(&self.categories, self.width, self.height, &prompted, feather, self.latent());
        let texts = prompts.values().map(|p| sdxl.encode_prompt(p.as_str().unwrap(), None, false).unwrap()).collect();
        Some((texts, masks))
    }

    /// Per latent pixel over the largest strength, and that largest strength.
    fn strengths(&self, case: &Value) -> Option<(Vec<f64>, f64)> {
        let default = case["init_strength"].as_f64()?;
        let own: HashMap<u32, f64> = (case["strengths"].as_object().into_iter().flatten())
            .map(|(k, v)| (self.names[k], v.as_f64().unwrap()))
            .collect();
        let background = case["background_strength"].as_f64();
        let per_pixel: Vec<f64> = (self.categories.iter())
            .map(|c| match (c, background) {
                (0, Some(b)) => b,
                _ => own.get(c).copied().unwrap_or(default),
            })
            .collect();
        let largest = own.values().copied().chain(background).fold(default, f64::max);
        let feather = case["feather"].as_u64().unwrap() as usize;
        let map = relative_strengths(&per_pixel, self.width, self.height, largest, feather, self.latent());
        Some((map, largest))
    }
}

fn case_job(case: &Value, strength: Option<f64>) -> TextToImage {
    let mut job = job(case);
    job.sampling.strength = strength;
    job
}

/// The case's latents, from diffusers' own encoding of the render where it starts from it (the VAE
/// encoder is held to diffusers on its own, within 1e-4).
fn denoise_case(
    sdxl: &Sdxl,
    case: &Value,
    records: &SafeTensors,
    scene: &Scene,
    control: Vec<ControlNetUse>,
) -> Vec<f32> {
    let regions = scene.regions(sdxl, case);
    let regions = regions.as_ref().map(|(texts, masks)| Regions { texts, masks: masks.clone() });
    let strengths = scene.strengths(case);
    let job = case_job(case, strengths.as_ref().map(|s| s.1));
    let tensor = |key: &str| case["tensors"][key].as_str().map(|name| records.values(name).unwrap().1);
    let init = tensor("init_mean").map(|mean| InitLatents { mean, std: tensor("init_std").unwrap() });
    let guided = job.sampling.guided();
    let text = sdxl.encode_prompt_as(job.sampling.prompt_syntax, &job.prompt, None, guided).unwrap();
    let count = regions.as_ref().map_or(0, |r| r.texts.len());
    // The IP-Adapter over its style images, every region's row seeing the positive row's tokens.
    let ip = &case["ip"];
    let style = ip.is_object().then(|| {
        let ctx = ctx();
        let adapter_file = fixture(&format!("workflow/{}", ip["adapter"].as_str().unwrap()));
        let adapter = IpAdapter::load(&ctx, &adapter_file, sdxl.unet(), Dtype::F32).unwrap();
        let encoder =
            ClipVisionModelWithProjection::load_folder(&ctx, &fixture("workflow/image_encoder"), Dtype::F32).unwrap();
        let images: Vec<RgbImage> = (ip["images"].as_array().unwrap().iter())
            .map(|f| read_image(&fixture(&format!("workflow/{}", f.as_str().unwrap()))).unwrap())
            .collect();
        (adapter, encoder, images, IpScale::All(ip["scale"].as_f64().unwrap() as f32))
    });
    let tokens = style.as_ref().map(|(adapter, encoder, images, scale)| {
        let preprocess = ClipPreprocess::square(encoder.config().image_size);
        let guide = ImageGuide { adapter, encoder, preprocess: &preprocess, images, scale };
        guide.tokens(guided).unwrap()
    });
    let ip_use =
        style.as_ref().map(|(adapter, _, images, scale)| IpAdapterUse { adapter, scale, images: images.len() });
    let denoiser = Denoiser::record(sdxl, &job.sampling, &control, ip_use, 1, text.tokens, count).unwrap();
    let image = read_image(&fixture("workflow/control.png")).unwrap();
    let item = ItemInputs {
        seed: job.seed,
        text: &text,
        control_images: control.iter().map(|_| vec![&image]).collect(),
        ip_tokens: tokens.as_deref(),
        init: init.as_ref(),
        regions: regions.as_ref(),
        strength: strengths.as_ref().map(|(map, _)| &map[..]),
    };
    denoiser.run(&[item], &mut |_, _| {}).unwrap().latents.remove(0)
}

#[test]
fn prompts_and_strengths_per_region_match_comfyuis_semantics_in_f32() {
    let (categories, width, height, names) = scene();
    let scene = Scene { categories, width, height, names };
    let dir = fixture("workflow");
    let json: Value = serde_json::from_slice(&std::fs::read(dir.join("regions.json")).unwrap()).unwrap();
    let records = SafeTensors::open(&dir.join("regions.safetensors")).unwrap();
    let sdxl = Sdxl::load(&ctx(), &fixture("pipeline/tiny-sdxl"), Dtype::F32, &mut |_| {}).unwrap();
    let net = ControlNetModel::load(&ctx(), &dir.join("controlnet"), sdxl.unet_config(), Dtype::F32).unwrap();
    for case in json["cases"].as_array().unwrap() {
        let name = case["name"].as_str().unwrap();
        let control = match &case["control"] {
            Value::Null => Vec::new(),
            c => {
                assert_eq!(c["image"], "control.png");
                vec![ControlNetUse {
                    net: &net,
                    control_types: &[],
                    scale: c["scale"].as_f64().unwrap() as f32,
                    start: c["start"].as_f64().unwrap(),
                    end: c["end"].as_f64().unwrap(),
                }]
            }
        };
        let latents = denoise_case(&sdxl, case, &records, &scene, control);
        let (_, want) = records.values(case["tensors"]["latents"].as_str().unwrap()).unwrap();
        let rel = relative_l2(&latents, &want);
        eprintln!("{name}: latents rel L2 {rel:.2e}");
        assert!(rel <= 1e-5, "case {name}: latents relative L2 error {rel:.2e}");
    }
}

#[test]
fn one_region_over_everything_is_its_plain_prompt_and_one_strength_everywhere_is_plain_img2img() {
    let (categories, width, height, names) = scene();
    let scene = Scene { categories, width, height, names };
    let json: Value =
        serde_json::from_slice(&std::fs::read(fixture("workflow").join("regions.json")).unwrap()).unwrap();
    let case = &json["cases"][0];
    let sdxl = Sdxl::load(&ctx(), &fixture("pipeline/tiny-sdxl"), Dtype::F16, &mut |_| {}).unwrap();
    let denoise = |job: &TextToImage, guides: &Guides| sdxl.denoise(job, guides, &mut |_, _| {}).unwrap().latents;

    // Every pixel in the one prompted category: the scene prompt's mask is 0 everywhere.
    let everything = vec![1u32; width * height];
    let masks = region_masks(&everything, width, height, &[1], 2, scene.latent());
    let region = "a shiny red apple";
    let texts = [sdxl.encode_prompt(region, None, false).unwrap()];
    let regions = Regions { texts: &texts, masks };
    let job = case_job(case, None);
    let masked = denoise(&job, &Guides { regions: Some(&regions), ..Default::default() });
    let plain = denoise(&TextToImage { prompt: region.into(), ..job.clone() }, &Guides::default());
    assert!(masked == plain, "one region over everything differs from its plain prompt");

    // One strength everywhere: every pixel at the largest strength.
    let render = read_image(&fixture("scenes/folders/orchard-a/shaded.png")).unwrap();
    let map = relative_strengths(&vec![0.6; width * height], width, height, 0.6, 3, scene.latent());
    let job = case_job(case, Some(0.6));
    let strength = denoise(&job, &Guides { init: Some(&render), strength: Some(&map), ..Default::default() });
    let img2img = denoise(&job, &Guides { init: Some(&render), ..Default::default() });
    assert!(strength == img2img, "one strength everywhere differs from plain img2img");
}
