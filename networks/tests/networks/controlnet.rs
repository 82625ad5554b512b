//! ControlNetModel against diffusers on the tiny SDXL's ControlNets
//! (tools/make_workflow_fixtures.py): every residual, from the diffusers folder, the full and
//! the small variants, the same weights as one diffusers-named file and as an original (cldm)
//! file, in f32 and f16.

use crate::forward::errors;
use vkdiff_formats::SafeTensors;
use vkdiff_networks::unet_checkpoint;
use vkdiff_networks::{nchw_to_nhwc, nhwc_to_nchw, ControlNetInputs, ControlNetModel};
use vkdiff_runtime::{listing_variants, Context, Dtype, Tensor};
use vkdiff_testkit::fixture;
use vkdiff_testkit::{assert_network_kernels, ctx};

fn unet_config() -> vkdiff_networks::UNetConfig {
    let tiny = fixture("pipeline/tiny-sdxl");
    unet_checkpoint(&ctx(), &tiny, Dtype::F32).unwrap().0
}

fn upload(ctx: &Context, rec: &SafeTensors, name: &str, dtype: Dtype, nhwc: bool) -> Tensor {
    let (s, v) = rec.values(name).unwrap();
    if nhwc {
        ctx.upload(&[s[0], s[2], s[3], s[1]], dtype, &nchw_to_nhwc(&v, [s[0], s[1], s[2], s[3]])).unwrap()
    } else {
        ctx.upload(&s, dtype, &v).unwrap()
    }
}

/// Runs `model` on the recorded inputs and compares each residual with `records[name]`.
fn check(path: &str, records_of: &str, dtype: Dtype, tol: f64) {
    let ctx = ctx();
    let rec = SafeTensors::open(&fixture("workflow").join("records.safetensors")).unwrap();
    let net = ControlNetModel::load(&ctx, &fixture("workflow").join(path), &unet_config(), dtype).unwrap();
    let input = |name: &str, nhwc: bool| upload(&ctx, &rec, &format!("cn.input.{name}"), dtype, nhwc);
    let sample = input("sample", true);
    let context = input("encoder_hidden_states", false);
    let text_embeds = input("text_embeds", false);
    let time_ids = upload(&ctx, &rec, "cn.input.time_ids", Dtype::F32, false);
    let timesteps = upload(&ctx, &rec, "cn.input.timestep", Dtype::F32, false);
    let hint = net.encode_condition(&input("controlnet_cond", true)).unwrap();
    let inputs = ControlNetInputs {
        sample: &sample,
        timesteps: &timesteps,
        encoder_hidden_states: &context,
        added: Some((&text_embeds, &time_ids)),
        hint: &hint,
        scale: 1.0,
        control_types: &[],
        add_to: None,
    };
    let (pass, ran) = listing_variants(|| net.record(&inputs).unwrap());
    assert_network_kernels(&ctx, dtype, &ran, 64, &format!("ControlNet {path} {dtype:?}"));
    pass.project_conditioning().unwrap();
    pass.run().unwrap();
    let r = &pass.residuals;
    let names: Vec<String> = (0..r.down.len()).map(|k| format!("down.{k}")).chain(["mid".into()]).collect();
    for (t, name) in r.down.iter().chain([&r.mid]).zip(names) {
        let (shape, want) = rec.values(&format!("cn.{records_of}.{name}")).unwrap();
        let s = t.shape();
        assert_eq!([s[0], s[3], s[1], s[2]], [shape[0], shape[1], shape[2], shape[3]], "{path} {name}");
        let got = nhwc_to_nchw(&t.download().unwrap(), [s[0], s[1], s[2], s[3]]);
        let (rel, _) = errors(&got, &want);
        assert!(rel <= tol, "{path} {dtype:?} residual {name}: relative L2 error {rel:.2e} > {tol:.0e}");
    }
    assert!(
        !rec.entries.contains_key(&format!("cn.{records_of}.down.{}", r.down.len())),
        "{path}: fewer residuals than diffusers"
    );
}

#[test]
fn controlnets_match_diffusers() {
    for dtype in [Dtype::F32, Dtype::F16] {
        let tol = if dtype == Dtype::F32 { 1e-4 } else { 1e-2 };
        check("controlnet", "controlnet", dtype, tol);
        check("controlnet-small", "controlnet-small", dtype, tol);
    }
}

#[test]
fn single_file_layouts_give_the_same_controlnet() {
    check("controlnet-cldm.safetensors", "controlnet", Dtype::F32, 1e-4);
    check("controlnet/diffusion_pytorch_model.fp16.safetensors", "controlnet", Dtype::F32, 1e-4);
}

#[test]
fn a_controlnet_for_another_unet_is_one_clear_error() {
    let mut other = unet_config();
    other.block_out_channels = vec![32, 64, 128];
    let err = ControlNetModel::load(&ctx(), &fixture("workflow").join("controlnet"), &other, Dtype::F32)
        .err()
        .expect("mismatch must fail")
        .to_string();
    assert!(err.contains("block_out_channels") && err.contains("another model"), "{err}");
    let err =
        ControlNetModel::load(&ctx(), &fixture("workflow").join("lora-peft.safetensors"), &unet_config(), Dtype::F32)
            .err()
            .expect("not a ControlNet")
            .to_string();
    assert!(err.contains("not a ControlNet"), "{err}");
}
