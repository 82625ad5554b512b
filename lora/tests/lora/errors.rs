//! User mistakes and unsupported files: one clear line naming the file and the key.

use crate::common::*;
use vkdiff_lora::{Error, LoraFile, LoraMerger, Targets};
use vkdiff_runtime::Dtype;

const Q: &str = "down_blocks.1.attentions.0.transformer_blocks.0.attn1.to_q";

fn pair(name: &str, down: &[usize], up: &[usize]) -> Vec<(String, Vec<usize>, Vec<f32>)> {
    let n = |s: &[usize]| s.iter().product::<usize>();
    vec![
        (format!("{name}.lora_down.weight"), down.to_vec(), random(n(down), 1)),
        (format!("{name}.lora_up.weight"), up.to_vec(), random(n(up), 2)),
    ]
}

fn one_line(e: &Error) -> String {
    let s = e.to_string();
    assert!(!s.contains('\n'), "error spans lines: {s}");
    s
}

fn open_err(name: &str, tensors: &[(String, Vec<usize>, Vec<f32>)]) -> String {
    let path = scratch(name).join("lora.safetensors");
    write(&path, tensors, &[]);
    let e = LoraFile::open(&path).err().unwrap_or_else(|| panic!("{name} opened"));
    let s = one_line(&e);
    assert!(s.contains(name), "{s}");
    s
}

#[test]
fn unsupported_and_malformed_files() {
    let mut t = pair("lora_unet_input_blocks_3_1_proj_in", &[4, 64], &[64, 4]);
    t.push(("lora_unet_input_blocks_4_1_proj_out.hada_w1_a".into(), vec![64, 4], random(256, 3)));
    let s = open_err("loha.safetensors", &t);
    assert!(s.contains("`lora_unet_input_blocks_4_1_proj_out.hada_w1_a`") && s.contains("LoHa"), "{s}");

    let s = open_err(
        "lokr.safetensors",
        &[("lora_te1_text_model_encoder_layers_0_mlp_fc1.lokr_w1".into(), vec![4, 4], random(16, 4))],
    );
    assert!(s.contains("LoKr"), "{s}");
    let s = open_err("dora.safetensors", &[("lora_unet_x.dora_scale".into(), vec![4], random(4, 4))]);
    assert!(s.contains("DoRA"), "{s}");
    let s = open_err("mid.safetensors", &[("lora_unet_x.lora_mid.weight".into(), vec![4, 4, 3, 3], random(144, 4))]);
    assert!(s.contains("lora_mid"), "{s}");
    let s = open_err("peft-dora.safetensors", &[(format!("unet.{Q}.lora_magnitude_vector"), vec![64], random(64, 4))]);
    assert!(s.contains("DoRA"), "{s}");

    let s =
        open_err("checkpoint.safetensors", &[("model.diffusion_model.out.2.weight".into(), vec![4, 4], random(16, 5))]);
    assert!(s.contains("`model.diffusion_model.out.2.weight`") && s.contains("not part of any LoRA layout"), "{s}");

    let half = pair("lora_unet_input_blocks_3_1_proj_in", &[4, 64], &[64, 4]);
    let s = open_err("no-up.safetensors", &half[..1]);
    assert!(s.contains("`lora_unet_input_blocks_3_1_proj_in`") && s.contains("up"), "{s}");

    let s = open_err("ranks.safetensors", &pair("lora_unet_input_blocks_3_1_proj_in", &[4, 64], &[64, 3]));
    assert!(s.contains("not LoRA factors"), "{s}");
}

fn apply_err(name: &str, tensors: &[(String, Vec<usize>, Vec<f32>)], unet_only: bool) -> String {
    let nets = tiny_sdxl(Dtype::F32);
    let before = nets.params().map(snapshot);
    let path = scratch(name).join("lora.safetensors");
    write(&path, tensors, &[]);
    let lora = LoraFile::open(&path).unwrap();
    let targets =
        if unet_only { Targets::unet_only(&nets.unet) } else { Targets::sdxl(&nets.unet, &nets.clip_l, &nets.big_g) };
    let mut merger = LoraMerger::new();
    let e = merger.apply(&targets, &[(&lora, 1.0)]).err().unwrap_or_else(|| panic!("{name} merged"));
    assert!(!merger.is_merged());
    for (b, p) in before.iter().zip(nets.params()) {
        assert_restored(name, b, p);
    }
    let s = one_line(&e);
    assert!(s.contains(name), "{s}");
    s
}

#[test]
fn unmatched_modules_are_listed_with_a_count() {
    let mut t = pair("lora_unet_input_blocks_3_1_proj_in", &[4, 64], &[64, 4]);
    for i in 0..7 {
        t.extend(pair(&format!("lora_unet_input_blocks_9{i}_1_proj_in"), &[4, 64], &[64, 4]));
    }
    let s = apply_err("unknown.safetensors", &t, false);
    assert!(
        s.contains("7 LoRA module(s) match no weight")
            && s.contains("`lora_unet_input_blocks_90_1_proj_in`")
            && s.contains("and 2 more"),
        "{s}"
    );

    let s = apply_err(
        "no-text-encoders.safetensors",
        &pair("lora_te1_text_model_encoder_layers_0_mlp_fc1", &[4, 64], &[128, 4]),
        true,
    );
    assert!(s.contains("1 LoRA module(s)") && s.contains("lora_te1_text_model_encoder_layers_0_mlp_fc1"), "{s}");
}

#[test]
fn wrong_shapes_name_key_weight_and_shapes() {
    let peft = |(k, s, v): (String, Vec<usize>, Vec<f32>)| {
        (k.replace(".lora_down.", ".lora_A.").replace(".lora_up.", ".lora_B."), s, v)
    };
    let t: Vec<_> = pair(&format!("unet.{Q}"), &[4, 32], &[64, 4]).into_iter().map(peft).collect();
    let s = apply_err("shape.safetensors", &t, false);
    assert!(
        s.contains(&format!("`unet.{Q}`"))
            && s.contains(&format!("`{Q}.weight`"))
            && s.contains("[64, 64]")
            && s.contains("[64, 32]"),
        "{s}"
    );

    // A linear LoRA aimed at a 3×3 conv.
    let s = apply_err("conv.safetensors", &pair("lora_unet_input_blocks_1_0_in_layers_2", &[2, 32], &[32, 2]), false);
    assert!(s.contains("[32, 32, 3, 3]") && s.contains("[32, 32]"), "{s}");
}
