//! The conditioning's projections (the cross-attentions' keys and values of the prompt and of
//! the image tokens): recorded apart from the evaluation, run once per conditioning, with their
//! weights in host memory.

use crate::forward::{ip_adapter, Inputs};
use vkdiff_formats::SafeTensors;
use vkdiff_networks::{unet_checkpoint, ClipTextModel, TextEncoderSlot, UNet};
use vkdiff_runtime::Dtype;
use vkdiff_testkit::{ctx, fixture, private_ctx};

/// A recorded pass takes a new prompt and new image tokens by projecting them again, and then
/// gives exactly what a pass recorded for them gives.
#[test]
fn a_new_conditioning_is_projected_without_recording_again() {
    let (ctx, dtype) = (ctx(), Dtype::F32);
    let (config, ckpt) = unet_checkpoint(&ctx, &fixture("unet").join("sdxl3"), dtype).unwrap();
    let unet = UNet::load(&config, &ckpt).unwrap();
    let io = SafeTensors::open(&fixture("unet").join("sdxl3/io.safetensors")).unwrap();
    let inputs = Inputs::read(&ctx, &io, dtype);
    let ip = [ip_adapter(&ctx, &unet, &io, "sdxl3", dtype)];
    let evaluate = |pass: &vkdiff_networks::UNetPass| {
        pass.project_conditioning().unwrap();
        pass.run().unwrap();
        pass.output.download().unwrap()
    };
    let pass = unet.record(&inputs.unet(None, &ip)).unwrap();
    let first = evaluate(&pass);

    for t in [&inputs.context, &ip[0].tokens] {
        let other: Vec<f32> = t.download().unwrap().iter().rev().map(|v| 0.5 * v).collect();
        t.write(&other).unwrap();
    }
    let second = evaluate(&pass);
    assert_ne!(first, second, "the new prompt and image tokens changed nothing");
    let fresh = unet.record(&inputs.unet(None, &ip)).unwrap();
    assert_eq!(evaluate(&fresh), second, "projected again, the pass must equal one recorded for the new inputs");
}

/// What runs once per conditioning reads its weights from host memory: every cross-attention's
/// key and value weights, and both text encoders whole.
#[test]
fn weights_read_once_per_conditioning_live_in_host_memory() {
    let dtype = Dtype::F16;
    let ctx = private_ctx();
    let (config, ckpt) = unet_checkpoint(&ctx, &fixture("unet").join("sdxl3"), dtype).unwrap();
    let unet = UNet::load(&config, &ckpt).unwrap();
    let kv_bytes: u64 =
        unet.cross_attention_channels().iter().map(|&c| (2 * c * config.cross_attention_dim * 2) as u64).sum();
    assert_eq!(ctx.host_bytes(), kv_bytes, "host memory: the keys' and values' weights, nothing else");
    let (device, host) = (ctx.live_bytes(), ctx.host_bytes());
    drop(unet);
    drop(ckpt);
    assert_eq!((ctx.live_bytes(), ctx.host_bytes()), (0, 0), "the UNet's memory, freed with it");
    assert!(device > host, "the rest of the UNet stays on the device");

    let model = fixture("pipeline").join("tiny-sdxl");
    let encoders = [TextEncoderSlot::ClipL, TextEncoderSlot::BigG]
        .map(|slot| ClipTextModel::load_sdxl(&ctx, &model, slot, dtype).unwrap());
    assert_eq!(ctx.live_bytes(), 0, "a text encoder's weights on the device");
    assert!(ctx.host_bytes() > 0);
    drop(encoders);
}
