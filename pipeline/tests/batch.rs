//! Batching is free of side effects: images denoised together, B per UNet pass, come out bit for
//! bit as each does alone, with the whole workflow (ControlNet, IP-Adapter, LoRAs, guidance,
//! ancestral noise), in f16 and f32, with tensors split into bands past the binding limit, and
//! with the recording split into one submission per dispatch. A private device context: the
//! binding limit and the submission budget are changed here. The dispatches each run makes are
//! counted: a batch split into bands must run more than one image does, others as many.

use vkdiff_pipeline::images::{read_image, ControlDepth};
use vkdiff_pipeline::{
    ControlNetSettings, Denoiser, IpAdapterSettings, IpScale, ItemInputs, LoraSetting, ModelSettings, SamplerKind,
    Sampling, WorkflowModels,
};
use vkdiff_render::control::ControlKind;
use vkdiff_runtime::{Context, Dtype, SubmitBudget};
use vkdiff_testkit::fixture;

fn settings(precision: Dtype) -> ModelSettings {
    ModelSettings {
        model: fixture("pipeline/tiny-sdxl"),
        vae: None,
        unet: None,
        precision,
        controlnets: vec![ControlNetSettings {
            model: fixture("workflow/controlnet"),
            controls: vec![ControlKind::Depth],
            depth_mode: ControlDepth::Inverse,
            scale: 0.7,
            start: 0.0,
            end: 1.0,
        }],
        ip_adapter: Some(IpAdapterSettings {
            adapter: fixture("workflow/ip-adapter_tiny.safetensors"),
            encoder: fixture("workflow/image_encoder"),
            scale: IpScale::All(0.6),
        }),
        loras: vec![LoraSetting { path: fixture("workflow/lora-peft.safetensors"), strength: 0.5 }],
        vae_tiling: Default::default(),
    }
}

/// How the batch of three is run besides: tensors split past a binding limit (the denoiser's,
/// not the encoders', whose weights are larger than the tensors split), or its recording
/// submitted one dispatch at a time.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Split {
    None,
    Bands(u64),
    Submissions,
}

/// Three images denoised each alone, then all in one batch.
struct Runs {
    alone: Vec<Vec<f32>>,
    together: Vec<Vec<f32>>,
    /// Dispatches of the first image's run alone, and of the batch's run.
    dispatches: (usize, usize),
}

/// Latents of three images: each alone, then all in one batch, run as `split` says; every
/// recording timed, so that the dispatches each run makes are counted.
fn alone_and_together(ctx: &Context, precision: Dtype, size: (usize, usize), split: Split) -> Runs {
    let binding_limit = match split {
        Split::Bands(limit) => Some(limit),
        _ => None,
    };
    let models = WorkflowModels::load(ctx, &settings(precision), &mut |_| {}).unwrap();
    let sampling = Sampling {
        steps: if binding_limit.is_some() { 1 } else { 3 },
        guidance_scale: 6.0,
        sampler: SamplerKind::EulerAncestral,
        schedule: Default::default(),
        width: size.0,
        height: size.1,
        size_conditioning: Default::default(),
        strength: None,
        prompt_syntax: Default::default(),
    };
    let sdxl = &models.sdxl;
    let texts = [
        sdxl.encode_prompt("white mushrooms", None, true).unwrap(),
        sdxl.encode_prompt("brown caps on compost", Some("blurry"), true).unwrap(),
    ];
    let styles =
        [read_image(&fixture("workflow/style-1.png")).unwrap(), read_image(&fixture("workflow/style-2.png")).unwrap()];
    let tokens: Vec<Vec<f32>> =
        styles.iter().map(|s| models.image_guide(std::slice::from_ref(s)).unwrap().tokens(true).unwrap()).collect();
    let control = read_image(&fixture("workflow/control.png")).unwrap();
    let flipped =
        vkdiff_pipeline::RgbImage { pixels: control.pixels.iter().rev().copied().collect(), ..control.clone() };
    let items = [
        ItemInputs {
            seed: 11,
            text: &texts[0],
            control_images: vec![vec![&control]],
            ip_tokens: Some(&tokens[0]),
            init: None,
            regions: None,
            strength: None,
        },
        ItemInputs {
            seed: 12,
            text: &texts[1],
            control_images: vec![vec![&flipped]],
            ip_tokens: Some(&tokens[1]),
            init: None,
            regions: None,
            strength: None,
        },
        ItemInputs {
            seed: 13,
            text: &texts[1],
            control_images: vec![vec![&control]],
            ip_tokens: Some(&tokens[0]),
            init: None,
            regions: None,
            strength: None,
        },
    ];
    if let Some(limit) = binding_limit {
        ctx.choose(|c| c.binding_limit = limit);
    }
    let record = |batch| {
        Denoiser::record(sdxl, &sampling, &models.control_uses(), models.ip_use(1), batch, texts[0].tokens, 0).unwrap()
    };
    ctx.set_profiling(true);
    let one = record(1);
    let (alone, counts): (Vec<Vec<f32>>, Vec<usize>) = items
        .iter()
        .map(|item| {
            let (mut out, timed) = ctx.profiled(|| one.run(std::slice::from_ref(item), &mut |_, _| {}).unwrap());
            (out.latents.remove(0), timed.len())
        })
        .unzip();
    drop(one);
    if split == Split::Submissions {
        ctx.choose(|c| c.submit_budget = SubmitBudget { flops: 0.0, dispatches: 1, ..c.submit_budget });
    }
    ctx.set_profiling(true);
    let three = record(3);
    let (together, timed) = ctx.profiled(|| three.run(&items, &mut |_, _| {}).unwrap().latents);
    Runs { alone, together, dispatches: (counts[0], timed.len()) }
}

fn check(precision: Dtype, size: (usize, usize), split: Split) {
    let ctx = Context::new(&Default::default(), vkdiff_testkit::settings())
        .unwrap_or_else(|e| panic!("these tests need a Vulkan device and found none usable: {e}"));
    let Runs { alone, together, dispatches: (one, three) } = alone_and_together(&ctx, precision, size, split);
    // The batch is one recording of the same layers: as many dispatches as one image, unless
    // its tensors, three times one image's, were cut into more bands past the binding limit.
    match split {
        Split::Bands(limit) => assert!(three > one, "{limit} bytes: the batch ran {three} dispatches, one image {one}"),
        _ => assert_eq!(three, one, "{split:?}: dispatches of the batch and of one image"),
    }
    for (k, (a, t)) in alone.iter().zip(&together).enumerate() {
        let differ = a.iter().zip(t).filter(|(x, y)| x.to_bits() != y.to_bits()).count();
        assert_eq!(
            differ,
            0,
            "{precision:?}, {split:?}: image {k} differs in {differ} of {} latents \
            between batch 1 and batch 3",
            a.len()
        );
    }
    assert_ne!(together[0], together[2], "images with other seeds and styles differ");
}

#[test]
fn a_batch_gives_each_image_bit_for_bit_in_f16() {
    check(Dtype::F16, (64, 96), Split::None);
}

#[test]
fn a_batch_gives_each_image_bit_for_bit_in_f32() {
    check(Dtype::F32, (64, 96), Split::None);
}

#[test]
fn a_batch_split_into_bands_gives_each_image_bit_for_bit() {
    // 1 MiB: above every weight; the batch's activations, skip concatenations and attention
    // operands pass it, and many of one image's too.
    check(Dtype::F32, (256, 384), Split::Bands(1 << 20));
}

#[test]
fn a_batch_submitted_one_dispatch_at_a_time_gives_each_image_bit_for_bit() {
    // What a small submission budget does on a GPU with a short watchdog: the same commands,
    // each chunk opened by a barrier over everything before it.
    check(Dtype::F16, (64, 96), Split::Submissions);
}
