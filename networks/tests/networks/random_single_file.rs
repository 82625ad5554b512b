//! Random weights written in the original single-file layout (for stable-diffusion.cpp beside
//! vkdiff in `bench report`): the names and shapes diffusers' converters give, the random
//! checkpoints' values, and vkdiff's own loaders reading every tensor back.

use std::collections::BTreeMap;
use vkdiff_formats::SafeTensors;
use vkdiff_networks::weights::Checkpoint;
use vkdiff_networks::{
    read_unet_config, unet_checkpoint, write_random_single_file, AutoencoderKl, ClipTextModel, SdxlConfigs,
    TextEncoderSlot, UNet, RANDOM_SEEDS,
};
use vkdiff_runtime::Dtype;
use vkdiff_testkit::{ctx, fixture, scratch};

fn shapes(file: &SafeTensors) -> BTreeMap<String, Vec<usize>> {
    file.entries.iter().map(|(k, e)| (k.clone(), e.shape.clone())).collect()
}

fn f16(values: Vec<f32>) -> Vec<f32> {
    values.into_iter().map(|v| half::f16::from_f32(v).to_f32()).collect()
}

#[test]
fn random_weights_in_the_original_layout_as_diffusers_converters_name_them() {
    let ctx = ctx();
    let tiny = fixture("pipeline").join("tiny-sdxl");
    let configs = SdxlConfigs {
        unet: read_unet_config(&tiny).unwrap(),
        clip_l: ClipTextModel::sdxl_config(&tiny, TextEncoderSlot::ClipL).unwrap(),
        big_g: ClipTextModel::sdxl_config(&tiny, TextEncoderSlot::BigG).unwrap(),
        vae: AutoencoderKl::sdxl_config(&tiny).unwrap(),
    };
    let path = scratch("random-single-file").join("sdxl.safetensors");
    write_random_single_file(&ctx, &configs, &path).unwrap();
    let written = SafeTensors::open(&path).unwrap();
    // tools/make_pipeline_fixtures.py wrote the tiny model's single file, and diffusers'
    // from_single_file rebuilt the same pipeline from it.
    let reference = SafeTensors::open(&fixture("pipeline").join("tiny-sdxl.safetensors")).unwrap();
    let (got, want) = (shapes(&written), shapes(&reference));
    let differ: Vec<_> = got.iter().filter(|(k, s)| want.get(*k) != Some(s)).map(|(k, _)| k).collect();
    let missing: Vec<_> = want.keys().filter(|k| !got.contains_key(*k)).collect();
    assert!(differ.is_empty() && missing.is_empty(), "extra or reshaped: {differ:?}; missing: {missing:?}");

    // The values are the random checkpoints': a plain tensor, a q/k/v row block of OpenCLIP's
    // fused projection, its transposed text projection, and a 1×1-convolution VAE projection.
    let value = |name: &str| written.values(name).unwrap().1;
    let random = |seed, name: &str, shape: &[usize]| f16(Checkpoint::random_values(seed, name, shape));
    let g = configs.big_g.hidden_size;
    let conv_in = "model.diffusion_model.input_blocks.0.0.weight";
    assert_eq!(value(conv_in), random(RANDOM_SEEDS.unet, "conv_in.weight", &want[conv_in]));
    let fused = value("conditioner.embedders.1.model.transformer.resblocks.0.attn.in_proj_weight");
    let k = random(RANDOM_SEEDS.big_g, "text_model.encoder.layers.0.self_attn.k_proj.weight", &[g, g]);
    assert_eq!(fused[g * g..2 * g * g], k[..]);
    let p = configs.big_g.projection_dim.unwrap();
    let projection = random(RANDOM_SEEDS.big_g, "text_projection.weight", &[p, g]);
    let stored = value("conditioner.embedders.1.model.text_projection");
    assert_eq!(stored[1], projection[g], "stored transposed: [1][0] of the [{p}, {g}] weight");
    let q = "first_stage_model.decoder.mid.attn_1.q.weight";
    let c = want[q][0];
    assert_eq!(value(q), random(RANDOM_SEEDS.vae, "decoder.mid_block.attentions.0.to_q.weight", &[c, c]));

    // vkdiff's single-file loaders read it whole.
    let (config, ckpt) = unet_checkpoint(&ctx, &path, Dtype::F16).unwrap();
    UNet::load(&config, &ckpt).unwrap();
    assert_eq!(ckpt.unused(), Vec::<String>::new());
    for slot in [TextEncoderSlot::ClipL, TextEncoderSlot::BigG] {
        ClipTextModel::load_sdxl(&ctx, &path, slot, Dtype::F16).unwrap();
    }
    AutoencoderKl::load_sdxl(&ctx, &path, Dtype::F16).unwrap();
}
