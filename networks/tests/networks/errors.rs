//! Broken checkpoints and inputs: one error naming what is wrong.

use std::path::Path;
use vkdiff_networks::{single_file_unet_checkpoint, unet_checkpoint};
use vkdiff_networks::{UNet, UNetConfig, UNetInputs};
use vkdiff_runtime::{Dtype, Tensor};
use vkdiff_testkit::ctx;
use vkdiff_testkit::{fixture, scratch};

fn load_error(path: &Path) -> String {
    match unet_checkpoint(&ctx(), path, Dtype::F32).and_then(|(config, ckpt)| UNet::load(&config, &ckpt)) {
        Ok(_) => panic!("{} loaded", path.display()),
        Err(e) => e.to_string(),
    }
}

pub fn assert_one_line(message: &str, wants: &[&str]) {
    assert!(!message.contains('\n'), "not one line: {message}");
    for want in wants {
        assert!(message.contains(want), "`{message}` does not mention `{want}`");
    }
}

#[test]
fn truncated_single_file_names_the_tensor() {
    let bytes = std::fs::read(fixture("unet").join("sdxl3/sd_xl_single_file.safetensors")).unwrap();
    let path = scratch("unet-truncated").join("model.safetensors");
    std::fs::write(&path, &bytes[..bytes.len() * 2 / 3]).unwrap();
    assert_one_line(&load_error(&path), &["model.safetensors", "model.diffusion_model.", "truncated"]);
}

#[test]
fn not_a_safetensors_file() {
    let path = scratch("unet-garbage").join("model.safetensors");
    std::fs::write(&path, b"\xff\xff\xff\xff\xff\xff\x00\x00 certainly not a header").unwrap();
    assert_one_line(&load_error(&path), &["model.safetensors", "header"]);
}

#[test]
fn missing_tensor_names_both_layouts() {
    // A config asking for a third transformer block at the last level, which the file lacks.
    let (mut config, _) =
        unet_checkpoint(&ctx(), &fixture("unet").join("sdxl3/sd_xl_single_file.safetensors"), Dtype::F32).unwrap();
    config.transformer_layers_per_block = serde_json::from_str("[1, 1, 3]").unwrap();
    let path = fixture("unet").join("sdxl3/sd_xl_single_file.safetensors");
    let err = single_file_unet_checkpoint(&ctx(), &path, config, Dtype::F32)
        .and_then(|(config, ckpt)| UNet::load(&config, &ckpt))
        .err()
        .expect("loaded with a block the file lacks")
        .to_string();
    assert_one_line(
        &err,
        &[
            "model.diffusion_model.input_blocks.7.1.transformer_blocks.2.",
            "down_blocks.2.attentions.0.transformer_blocks.2.",
            "is missing",
            "single-file",
        ],
    );
}

#[test]
fn shape_mismatch_names_tensor_and_shapes() {
    let dir = scratch("unet-shape");
    let source = fixture("unet").join("heads/unet");
    for entry in std::fs::read_dir(&source).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(entry.path(), dir.join(entry.file_name())).unwrap();
    }
    let config = std::fs::read_to_string(source.join("config.json")).unwrap();
    let mut json: serde_json::Value = serde_json::from_str(&config).unwrap();
    json["cross_attention_dim"] = 40.into();
    std::fs::write(dir.join("config.json"), json.to_string()).unwrap();
    assert_one_line(&load_error(&dir), &["attn2.to_k.weight", "[32, 48]", "[32, 40]"]);
}

#[test]
fn folder_without_config() {
    let dir = scratch("unet-noconfig");
    assert_one_line(&load_error(&dir), &["config.json"]);
}

#[test]
fn unsupported_config_value_is_named() {
    let mut config: UNetConfig = UNetConfig::sdxl_base();
    config.up_block_types[0] = "SimpleCrossAttnUpBlock2D".into();
    let err = config.validate().unwrap_err().to_string();
    assert_one_line(&err, &["up_block_types", "SimpleCrossAttnUpBlock2D"]);
}

#[test]
fn latent_size_off_the_grid_is_rejected_before_recording() {
    let ctx = ctx();
    let (config, ckpt) = unet_checkpoint(&ctx, &fixture("unet").join("heads"), Dtype::F32).unwrap();
    let unet = UNet::load(&config, &ckpt).unwrap();
    let t = |shape: &[usize], dtype: Dtype| -> Tensor { ctx.zeros(shape, dtype).unwrap() };
    let (sample, steps, context, text, ids) = (
        t(&[2, 7, 8, 4], Dtype::F32),
        t(&[2], Dtype::F32),
        t(&[2, 10, 48], Dtype::F32),
        t(&[2, 40], Dtype::F32),
        t(&[2, 6], Dtype::F32),
    );
    let inputs = UNetInputs {
        sample: &sample,
        timesteps: &steps,
        encoder_hidden_states: &context,
        added: Some((&text, &ids)),
        control: None,
        ip: &[],
    };
    let err = unet.record(&inputs).err().expect("recorded a 7×8 latent").to_string();
    assert_one_line(&err, &["7×8", "multiple of 2"]);
}

#[test]
fn a_unet_only_file_has_no_text_encoders_or_vae() {
    let path = fixture("unet").join("sdxl3/sd_xl_single_file.safetensors");
    let te =
        vkdiff_networks::ClipTextModel::load_sdxl(&ctx(), &path, vkdiff_networks::TextEncoderSlot::BigG, Dtype::F32)
            .err()
            .unwrap()
            .to_string();
    assert_one_line(
        &te,
        &[
            "sd_xl_single_file.safetensors",
            "conditioner.embedders.1.model.token_embedding.weight",
            "both text encoders",
        ],
    );
    let vae = vkdiff_networks::AutoencoderKl::load_sdxl(&ctx(), &path, Dtype::F32).err().unwrap().to_string();
    assert_one_line(&vae, &["sd_xl_single_file.safetensors", "first_stage_model.", "with a VAE"]);
}

#[test]
fn a_text_encoder_of_the_wrong_width_names_the_tensor() {
    // text_encoder_2's weights under text_encoder's config: the first shape check names both.
    let dir = scratch("unet-te-width");
    let src = fixture("pipeline/tiny-sdxl");
    std::fs::create_dir_all(dir.join("text_encoder")).unwrap();
    std::fs::copy(src.join("text_encoder/config.json"), dir.join("text_encoder/config.json")).unwrap();
    std::fs::copy(src.join("text_encoder_2/model.safetensors"), dir.join("text_encoder/model.safetensors")).unwrap();
    let err =
        vkdiff_networks::ClipTextModel::load_sdxl(&ctx(), &dir, vkdiff_networks::TextEncoderSlot::ClipL, Dtype::F32)
            .err()
            .unwrap()
            .to_string();
    assert_one_line(&err, &["token_embedding.weight", "has shape [49408, 128]", "expects [49408, 64]"]);
}
