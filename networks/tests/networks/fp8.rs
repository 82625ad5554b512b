//! A UNet from an fp8 single file (weights in float8_e4m3fn, as fp8 SDXL checkpoints ship them),
//! held to diffusers on the same weights widened by torch (tools/make_fp8_fixtures.py); ComfyUI's
//! scaled fp8 is refused in one line rather than read unscaled.

use crate::forward::{errors, Inputs};
use crate::malformed::{read_parts, write_parts};
use serde_json::json;
use vkdiff_formats::SafeTensors;
use vkdiff_networks::{nhwc_to_nchw, single_file_unet_checkpoint, UNet, UNetConfig};
use vkdiff_runtime::Dtype;
use vkdiff_testkit::{ctx, fixture, scratch};

fn heads_config() -> UNetConfig {
    UNetConfig::from_file(&fixture("unet").join("heads/unet/config.json")).unwrap()
}

/// Tolerances as forward.rs's: summation order in f32, f16's rounding of activations in f16 (the
/// fp8 weights themselves are exact in both).
fn fp8_single_file(dtype: Dtype) {
    let ctx = ctx();
    let path = fixture("fp8/heads_e4m3.safetensors");
    let (config, ckpt) = single_file_unet_checkpoint(&ctx, &path, heads_config(), dtype).unwrap();
    let unet = UNet::load(&config, &ckpt).unwrap();
    assert_eq!(ckpt.unused(), Vec::<String>::new(), "tensors the UNet never read");
    let inputs = Inputs::read(&ctx, &SafeTensors::open(&fixture("unet").join("heads/io.safetensors")).unwrap(), dtype);
    let pass = unet.record(&inputs.unet(None, &[])).unwrap();
    pass.project_conditioning().unwrap();
    pass.run().unwrap();
    let s = pass.output.shape().to_vec();
    let got = nhwc_to_nchw(&pass.output.download().unwrap(), [s[0], s[1], s[2], s[3]]);
    let (_, want) = SafeTensors::open(&fixture("fp8/io.safetensors")).unwrap().values("out_plain").unwrap();
    let (rel, worst) = errors(&got, &want);
    let tolerance = if dtype == Dtype::F32 { 1e-4 } else { 1e-2 };
    assert!(rel < tolerance && worst < 20.0 * tolerance, "{dtype:?}: relative L2 error {rel:.3e}, worst {worst:.3e}");
}

#[test]
fn fp8_e4m3_single_file_f32() {
    fp8_single_file(Dtype::F32);
}

#[test]
fn fp8_e4m3_single_file_f16() {
    fp8_single_file(Dtype::F16);
}

#[test]
fn scaled_fp8_is_refused_naming_the_scale() {
    let stem = "model.diffusion_model.input_blocks.1.0.in_layers.2.";
    // ComfyUI's scaled fp8, then its newer quantized format.
    for scale in ["scale_weight", "weight_scale"] {
        let mut parts = read_parts(&fixture("fp8/heads_e4m3.safetensors"));
        assert_eq!(parts.header[&format!("{stem}weight")]["dtype"], "F8_E4M3");
        let at = parts.data.len();
        let entry = json!({"dtype": "F32", "shape": [], "data_offsets": [at, at + 4]});
        parts.header.insert(format!("{stem}{scale}"), entry);
        parts.data.extend(1f32.to_le_bytes());
        let path = scratch("scaled-fp8").join(format!("{scale}.safetensors"));
        write_parts(&path, &parts);
        let loaded = single_file_unet_checkpoint(&ctx(), &path, heads_config(), Dtype::F16)
            .and_then(|(config, ckpt)| UNet::load(&config, &ckpt));
        let err = loaded.err().expect("a scaled fp8 weight must be refused").to_string();
        let named = format!("tensor `{stem}weight`");
        assert!(err.contains(&named) && err.contains(&format!("fp8 scaled by `{stem}{scale}`")), "{err}");
    }
}
