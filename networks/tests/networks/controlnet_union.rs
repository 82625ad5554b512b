//! ControlNet-Union against diffusers' ControlNetUnionModel on the tiny SDXL
//! (tools/make_union_fixtures.py): one condition, two fused in one call, the ProMax-style single
//! file and a batch of two rows, in f32; the cldm layout with ComfyUI's names; the errors; and
//! the full-size loader's requests against the published files' key lists
//! (tools/make_union_key_list.py).

use crate::forward::errors;
use crate::malformed::{read_parts, write_parts};
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::path::Path;
use vkdiff_formats::SafeTensors;
use vkdiff_networks::weights::Checkpoint;
use vkdiff_networks::{
    nchw_to_nhwc, nhwc_to_nchw, ControlNetConfig, ControlNetInputs, ControlNetModel, UNetConfig, UnionCondition,
    SDXL_CONTROLNET_CONFIG,
};
use vkdiff_runtime::{Context, Dtype, Tensor};
use vkdiff_testkit::{ctx, fixture, scratch};

fn unet_config() -> UNetConfig {
    vkdiff_networks::read_unet_config(&fixture("pipeline/tiny-sdxl")).unwrap()
}

fn load(path: &Path) -> vkdiff_networks::Result<ControlNetModel> {
    ControlNetModel::load(&ctx(), path, &unet_config(), Dtype::F32)
}

fn model_path(model: &str) -> std::path::PathBuf {
    let workflow = fixture("workflow");
    match model {
        "base" => workflow.join("controlnet-union"),
        _ => workflow.join("controlnet-union-promax.safetensors"),
    }
}

fn upload(ctx: &Context, rec: &SafeTensors, name: &str, nhwc: bool) -> Tensor {
    let (s, v) = rec.values(name).unwrap();
    if nhwc {
        ctx.upload(&[s[0], s[2], s[3], s[1]], Dtype::F32, &nchw_to_nhwc(&v, [s[0], s[1], s[2], s[3]])).unwrap()
    } else {
        ctx.upload(&s, Dtype::F32, &v).unwrap()
    }
}

fn cases() -> Vec<Value> {
    let text = std::fs::read_to_string(fixture("workflow").join("union.json")).unwrap();
    serde_json::from_str::<Value>(&text).unwrap()["cases"].as_array().unwrap().clone()
}

/// `net`'s residuals (NCHW, down then mid) on a recorded case, with its conditions scaled as
/// diffusers' pipeline does: one condition unscaled in the fusion and residuals × its scale;
/// several scaled in the fusion and residuals × 1.
fn residuals(net: &ControlNetModel, case: &Value) -> Vec<Vec<f32>> {
    let ctx = ctx();
    let rec = SafeTensors::open(&fixture("workflow").join("union.safetensors")).unwrap();
    let name = case["name"].as_str().unwrap();
    let input = |k: &str, nhwc| upload(&ctx, &rec, &format!("{name}.input.{k}"), nhwc);
    let conds = case["conditions"].as_array().unwrap();
    let images: Vec<Tensor> = (0..conds.len()).map(|j| input(&format!("image.{j}"), true)).collect();
    let scale = |c: &Value| c["scale"].as_f64().unwrap() as f32;
    let single = conds.len() == 1;
    let conditions: Vec<UnionCondition> = conds
        .iter()
        .zip(&images)
        .map(|(c, image)| UnionCondition {
            image,
            control_type: c["mode"].as_u64().unwrap() as usize,
            scale: if single { 1.0 } else { scale(c) },
        })
        .collect();
    let types: Vec<usize> = conditions.iter().map(|c| c.control_type).collect();
    let sample = input("sample", true);
    let s = sample.shape();
    let hint = ctx.zeros(&[s[0], s[1], s[2], net.config().encoder.block_out_channels[0]], Dtype::F32).unwrap();
    net.encode_conditions_into(&conditions, &hint).unwrap();
    let (context, text_embeds) = (input("encoder_hidden_states", false), input("text_embeds", false));
    let (time_ids, timesteps) = (input("time_ids", false), input("timestep", false));
    let pass = net
        .record(&ControlNetInputs {
            sample: &sample,
            timesteps: &timesteps,
            encoder_hidden_states: &context,
            added: Some((&text_embeds, &time_ids)),
            hint: &hint,
            scale: if single { scale(&conds[0]) } else { 1.0 },
            control_types: &types,
            add_to: None,
        })
        .unwrap();
    pass.project_conditioning().unwrap();
    pass.run().unwrap();
    let r = &pass.residuals;
    r.down
        .iter()
        .chain([&r.mid])
        .map(|t| {
            let s = t.shape();
            nhwc_to_nchw(&t.download().unwrap(), [s[0], s[1], s[2], s[3]])
        })
        .collect()
}

/// The worst relative L2 error of `got` against the case's recorded residuals.
fn worst_error(case: &Value, got: &[Vec<f32>]) -> f64 {
    let rec = SafeTensors::open(&fixture("workflow").join("union.safetensors")).unwrap();
    let name = case["name"].as_str().unwrap();
    let names: Vec<String> = (0..got.len() - 1).map(|k| format!("down.{k}")).chain(["mid".into()]).collect();
    assert!(!rec.entries.contains_key(&format!("{name}.down.{}", got.len() - 1)), "fewer residuals than diffusers");
    got.iter().zip(&names).map(|(g, n)| errors(g, &rec.values(&format!("{name}.{n}")).unwrap().1).0).fold(0.0, f64::max)
}

#[test]
fn union_residuals_match_diffusers() {
    for case in cases() {
        let name = case["name"].as_str().unwrap();
        let net = load(&model_path(case["model"].as_str().unwrap())).unwrap();
        let want_types = if case["model"] == "base" { 6 } else { 8 };
        assert_eq!(net.control_types(), Some(want_types), "{name}");
        let rel = worst_error(&case, &residuals(&net, &case));
        eprintln!("union case {name}: worst relative L2 error {rel:.2e}");
        assert!(rel <= 1e-5, "union case {name}: relative L2 error {rel:.2e} > 1e-5");
    }
}

/// The base model's tensors in the cldm layout (controlnet-cldm.safetensors: the same base
/// weights) plus its union extras, `in_proj` named as ComfyUI saves it.
fn write_cldm_union() -> std::path::PathBuf {
    let mut parts = read_parts(&fixture("workflow").join("controlnet-cldm.safetensors"));
    let extras = read_parts(&fixture("workflow/controlnet-union/diffusion_pytorch_model.safetensors"));
    let extra_names = ["task_embedding", "transformer_layes.", "spatial_ch_projs.", "control_add_embedding."];
    for (name, entry) in &extras.header {
        if !extra_names.iter().any(|p| name.starts_with(p)) {
            continue;
        }
        let [from, to] = [0, 1].map(|i| entry["data_offsets"][i].as_u64().unwrap() as usize);
        let at = parts.data.len();
        parts.data.extend_from_slice(&extras.data[from..to]);
        let stored = name
            .replace("attn.in_proj_weight", "attn.in_proj.weight")
            .replace("attn.in_proj_bias", "attn.in_proj.bias");
        let moved = json!({"dtype": entry["dtype"], "shape": entry["shape"], "data_offsets": [at, at + to - from]});
        parts.header.insert(format!("control_model.{stored}"), moved);
    }
    let path = scratch("controlnet-union").join("union-cldm.safetensors");
    write_parts(&path, &parts);
    path
}

#[test]
fn the_cldm_layout_with_comfy_names_gives_the_same_residuals() {
    let case = cases().into_iter().find(|c| c["name"] == "two").unwrap();
    let cldm = load(&write_cldm_union()).unwrap();
    assert_eq!(cldm.control_types(), Some(6));
    assert_eq!(residuals(&cldm, &case), residuals(&load(&model_path("base")).unwrap(), &case));
}

#[test]
fn each_image_is_fused_without_its_batch_mates() {
    let ctx = ctx();
    let net = load(&model_path("base")).unwrap();
    let rows: Vec<Vec<f32>> =
        [0.2f32, 0.7].iter().map(|v| (0..64 * 64 * 3).map(|i| (i % 7) as f32 * v / 7.0).collect()).collect();
    let hint_of = |values: &[f32], b: usize| {
        let image = ctx.upload(&[b, 64, 64, 3], Dtype::F32, values).unwrap();
        let hint = ctx.zeros(&[b, 8, 8, 32], Dtype::F32).unwrap();
        let cond = [UnionCondition { image: &image, control_type: 2, scale: 0.9 }];
        net.encode_conditions_into(&cond, &hint).unwrap();
        hint.download().unwrap()
    };
    let both = hint_of(&rows.concat(), 2);
    let (first, second) = (hint_of(&rows[0], 1), hint_of(&rows[1], 1));
    assert_ne!(first, second);
    assert_eq!(both, [first, second].concat());
}

fn error_of<T>(r: vkdiff_networks::Result<T>) -> String {
    r.err().expect("must fail").to_string()
}

#[test]
fn union_misuse_is_one_clear_error() {
    let ctx = ctx();
    let union = load(&model_path("base")).unwrap();
    let plain = load(&fixture("workflow").join("controlnet")).unwrap();
    assert_eq!(plain.control_types(), None);
    let image = ctx.zeros(&[1, 64, 64, 3], Dtype::F32).unwrap();
    let hint = ctx.zeros(&[1, 8, 8, 32], Dtype::F32).unwrap();
    let cond = |control_type, scale| UnionCondition { image: &image, control_type, scale };
    let err = error_of(union.encode_conditions_into(&[cond(6, 1.0)], &hint));
    assert!(err.contains("control type 6 is out of range") && err.contains("has 6"), "{err}");
    let err = error_of(plain.encode_conditions_into(&[cond(1, 1.0), cond(3, 1.0)], &hint));
    assert!(err.contains("plain ControlNet takes one conditioning image"), "{err}");
    assert!(error_of(union.encode_conditions_into(&[], &hint)).contains("no conditioning image"));
    plain.encode_conditions_into(&[cond(0, 1.0)], &hint).unwrap();

    let (sample, timesteps) = (ctx.zeros(&[1, 8, 8, 4], Dtype::F32).unwrap(), ctx.zeros(&[1], Dtype::F32).unwrap());
    let context = ctx.zeros(&[1, 4, 192], Dtype::F32).unwrap();
    let (text, ids) = (ctx.zeros(&[1, 128], Dtype::F32).unwrap(), ctx.zeros(&[1, 6], Dtype::F32).unwrap());
    let record = |net: &ControlNetModel, types: &[usize]| {
        net.record(&ControlNetInputs {
            sample: &sample,
            timesteps: &timesteps,
            encoder_hidden_states: &context,
            added: Some((&text, &ids)),
            hint: &hint,
            scale: 1.0,
            control_types: types,
            add_to: None,
        })
        .map(|_| ())
    };
    assert!(error_of(record(&union, &[])).contains("needs its active control types"));
    assert!(error_of(record(&union, &[1, 6])).contains("control type 6 is out of range"));
    assert!(error_of(record(&plain, &[1])).contains("plain ControlNet takes no control types"));
    record(&union, &[1, 3]).unwrap();
}

#[test]
fn a_malformed_union_is_refused_naming_what_disagrees() {
    let dir = scratch("controlnet-union-config");
    let source = fixture("workflow/controlnet-union");
    let weights = "diffusion_pytorch_model.safetensors";
    std::fs::copy(source.join(weights), dir.join(weights)).unwrap();
    let mut config: Value =
        serde_json::from_str(&std::fs::read_to_string(source.join("config.json")).unwrap()).unwrap();
    config["num_control_type"] = json!(8);
    std::fs::write(dir.join("config.json"), config.to_string()).unwrap();
    let err = error_of(load(&dir));
    assert!(err.contains("num_control_type 8") && err.contains("6 rows"), "{err}");

    // A task_embedding as wide as no token, in the same bytes (the reader allows no gaps).
    let mut parts = read_parts(&model_path("promax"));
    let entry = parts.header.get_mut("task_embedding").unwrap();
    assert_eq!(entry["shape"], json!([8, 32]));
    entry["shape"] = json!([16, 16]);
    let path = scratch("controlnet-union-width").join("wide.safetensors");
    write_parts(&path, &parts);
    let err = error_of(load(&path));
    assert!(err.contains("`task_embedding` is [16, 16]") && err.contains("32 wide"), "{err}");
}

fn key_list(types: usize) -> BTreeMap<String, Vec<usize>> {
    let text = std::fs::read_to_string(fixture(&format!("controlnet_union/keys-{types}.tsv"))).unwrap();
    text.lines()
        .map(|line| {
            let (name, shape) = line.split_once('\t').unwrap();
            (name.to_string(), shape.split(',').map(|d| d.parse().unwrap()).collect())
        })
        .collect()
}

#[test]
fn the_full_size_union_asks_for_the_published_tensors() {
    let ctx = ctx();
    for types in [6, 8] {
        let mut config: Value = serde_json::from_str(SDXL_CONTROLNET_CONFIG).unwrap();
        config["num_control_type"] = json!(types);
        let config = ControlNetConfig::from_json(&config.to_string(), "union config").unwrap();
        let ckpt = Checkpoint::random(&ctx, Dtype::F16, 3);
        let net = ControlNetModel::build(config, &ckpt, &UNetConfig::sdxl_base()).unwrap();
        assert_eq!(net.control_types(), Some(types));
        let asked: BTreeMap<String, Vec<usize>> = ckpt.requests().into_iter().collect();
        let want = key_list(types);
        let extra: Vec<_> = asked.iter().filter(|(k, s)| want.get(*k) != Some(s)).collect();
        let missing: Vec<_> = want.keys().filter(|k| !asked.contains_key(*k)).collect();
        assert!(
            extra.is_empty() && missing.is_empty(),
            "{types} types: asked beyond the list {extra:?}; missing {missing:?}"
        );
    }
}
