//! Forward passes held to diffusers' float32 outputs.

use std::path::Path;
use vkdiff_formats::SafeTensors;
use vkdiff_networks::{
    nchw_to_nhwc, nhwc_to_nchw, Checkpoint, ControlResiduals, IpAdapterInput, IpLayer, Linear, UNet, UNetConfig,
    UNetInputs,
};
use vkdiff_networks::{single_file_unet_checkpoint, unet_checkpoint};
use vkdiff_runtime::{listing_variants, Context, Dtype, ProbeChoice, Tensor, Variant};
use vkdiff_testkit::fixture;
use vkdiff_testkit::{assert_network_kernels, ctx};

/// The recorded inputs of one fixture, on the device.
pub(crate) struct Inputs {
    pub sample: Tensor,
    pub timesteps: Tensor,
    pub context: Tensor,
    pub text_embeds: Tensor,
    pub time_ids: Tensor,
}

impl Inputs {
    pub fn read(ctx: &Context, io: &SafeTensors, dtype: Dtype) -> Inputs {
        Inputs {
            sample: upload_nhwc(ctx, io, "sample", dtype),
            timesteps: upload(ctx, io, "timestep", Dtype::F32),
            context: upload(ctx, io, "encoder_hidden_states", dtype),
            text_embeds: upload(ctx, io, "text_embeds", dtype),
            time_ids: upload(ctx, io, "time_ids", Dtype::F32),
        }
    }

    /// The UNet's inputs: these, with `control` and `ip`.
    pub fn unet<'a>(&'a self, control: Option<&'a ControlResiduals>, ip: &'a [IpAdapterInput]) -> UNetInputs<'a> {
        UNetInputs {
            sample: &self.sample,
            timesteps: &self.timesteps,
            encoder_hidden_states: &self.context,
            added: Some((&self.text_embeds, &self.time_ids)),
            control,
            ip,
        }
    }
}

fn upload_nhwc(ctx: &Context, io: &SafeTensors, name: &str, dtype: Dtype) -> Tensor {
    let (s, v) = io.values(name).unwrap();
    let shape = [s[0], s[1], s[2], s[3]];
    ctx.upload(&[s[0], s[2], s[3], s[1]], dtype, &nchw_to_nhwc(&v, shape)).unwrap()
}

fn upload(ctx: &Context, io: &SafeTensors, name: &str, dtype: Dtype) -> Tensor {
    let (s, v) = io.values(name).unwrap();
    ctx.upload(&s, dtype, &v).unwrap()
}

/// Relative L2 error of `got` against `want`, and the largest error in units of want's RMS.
pub fn errors(got: &[f32], want: &[f32]) -> (f64, f64) {
    let (mut diff, mut norm, mut worst) = (0.0f64, 0.0f64, 0.0f64);
    for (&g, &w) in got.iter().zip(want) {
        let d = (g as f64 - w as f64).abs();
        diff += d * d;
        norm += (w as f64) * (w as f64);
        worst = worst.max(d);
    }
    let rms = (norm / want.len() as f64).sqrt();
    ((diff / norm).sqrt(), worst / rms)
}

/// Runs every variant of a fixture through the UNet at `model` and compares with diffusers.
///
/// Tolerances: in f32 the only differences are summation order and the f32 transcendental
/// functions (measured relative L2 error ~2e-6 through 40-odd layers), so 1e-4 catches any wrong
/// index, scale or missing term (those give errors of order 1e-1 and more). In f16 every
/// activation and weight is stored with 11 significant bits (relative rounding 2^-11 ≈ 4.9e-4 per
/// tensor) and the error compounds over ~150 stored tensors along the deepest path; measured
/// relative L2 errors are ~2e-3, and 1e-2 is the bound.
fn check(fixture_name: &str, model: &Path, dtype: Dtype) {
    check_loaded(&ctx(), fixture_name, model, dtype, unet_checkpoint(&ctx(), model, dtype).unwrap());
}

fn check_loaded(
    ctx: &Context,
    fixture_name: &str,
    model: &Path,
    dtype: Dtype,
    (config, ckpt): (UNetConfig, Checkpoint),
) -> Vec<&'static Variant> {
    let io = SafeTensors::open(&fixture("unet").join(format!("{fixture_name}/io.safetensors"))).unwrap();
    let unet = UNet::load(&config, &ckpt).unwrap();
    assert_eq!(ckpt.unused(), Vec::<String>::new(), "{}: tensors the UNet never read", model.display());
    let inputs = Inputs::read(ctx, &io, dtype);
    let (down_shapes, _) = unet.residual_shapes(0, 0, 0);
    let control = ControlResiduals {
        down: (0..down_shapes.len()).map(|i| upload_nhwc(ctx, &io, &format!("control_down.{i}"), dtype)).collect(),
        mid: upload_nhwc(ctx, &io, "control_mid", dtype),
    };
    let ip = [ip_adapter(ctx, &unet, &io, fixture_name, dtype)];
    let tolerance = if dtype == Dtype::F32 { 1e-4 } else { 1e-2 };
    let mut kernels = Vec::new();
    for (variant, control, ip) in [
        ("out_plain", None, &[][..]),
        ("out_control", Some(&control), &[][..]),
        ("out_ip", None, &ip[..]),
        ("out_both", Some(&control), &ip[..]),
    ] {
        let (pass, ran) = listing_variants(|| unet.record(&inputs.unet(control, ip)).unwrap());
        // The fixtures' heads are of 64 values at most.
        assert_network_kernels(ctx, dtype, &ran, 64, &format!("{fixture_name} {dtype:?} {variant}"));
        kernels.extend(ran);
        pass.project_conditioning().unwrap();
        pass.run().unwrap();
        let s = pass.output.shape().to_vec();
        let got = nhwc_to_nchw(&pass.output.download().unwrap(), [s[0], s[1], s[2], s[3]]);
        let (_, want) = io.values(variant).unwrap();
        let (rel, worst) = errors(&got, &want);
        eprintln!(
            "{fixture_name} {} {dtype:?} {variant}: relative L2 error {rel:.2e}, worst {worst:.2e} RMS",
            model.display()
        );
        assert!(
            rel < tolerance && worst < 20.0 * tolerance,
            "{fixture_name} {dtype:?} {variant}: relative L2 error \
            {rel:.3e}, worst element {worst:.3e} of the RMS (bound {tolerance:.0e})"
        );
    }
    kernels
}

/// The fixture's IP-Adapter: random image tokens and per-layer weights keyed `ip_adapter.N`,
/// N = 2k + 1 for the k-th cross-attention (diffusers' processor numbering).
pub(crate) fn ip_adapter(
    ctx: &Context,
    unet: &UNet,
    io: &SafeTensors,
    fixture_name: &str,
    dtype: Dtype,
) -> IpAdapterInput {
    let file = SafeTensors::open(&fixture("unet").join(format!("{fixture_name}/ip_adapter.safetensors"))).unwrap();
    assert_eq!(
        file.entries.len(),
        2 * unet.cross_attention_channels().len(),
        "one to_k_ip/to_v_ip pair per cross-attention"
    );
    let linear = |name: String| Linear { weight: upload(ctx, &file, &name, dtype), bias: None };
    let layers = (0..unet.cross_attention_channels().len())
        .map(|k| IpLayer {
            to_k_ip: linear(format!("ip_adapter.{}.to_k_ip.weight", 2 * k + 1)),
            to_v_ip: linear(format!("ip_adapter.{}.to_v_ip.weight", 2 * k + 1)),
        })
        .collect();
    let scale = io.values("ip_scale").unwrap().1[0];
    IpAdapterInput {
        tokens: upload(ctx, io, "ip_tokens", dtype),
        scales: vec![scale; unet.cross_attention_channels().len()],
        layers,
    }
}

#[test]
fn sdxl_layout_diffusers_sharded_fp16_variant_f32() {
    check("sdxl3", &fixture("unet").join("sdxl3"), Dtype::F32);
}

#[test]
fn sdxl_layout_diffusers_sharded_fp16_variant_f16() {
    check("sdxl3", &fixture("unet").join("sdxl3"), Dtype::F16);
}

/// The tiny models' convolutions are too small to take Winograd's F(2×2, 3×3) where the plan
/// runs it (CPU devices); here all of them do, against the same diffusers outputs.
#[test]
fn sdxl_layout_f16_with_every_convolution_by_winograd() {
    let ctx = vkdiff_testkit::private_ctx();
    ctx.choose(|c| c.winograd_from = Some(0));
    // VK_NV_cooperative_matrix2's convolution, where a pass asks for it, takes them instead.
    let probe = ctx.choices().conv == ProbeChoice::Matrix2;
    let model = fixture("unet").join("sdxl3");
    let ran = check_loaded(&ctx, "sdxl3", &model, Dtype::F16, unet_checkpoint(&ctx, &model, Dtype::F16).unwrap());
    assert_eq!(ran.iter().any(|v| v.kernel == "winograd_input"), !probe, "Winograd's transforms ran");
}

#[test]
fn sdxl_layout_single_file_f32() {
    check("sdxl3", &fixture("unet").join("sdxl3/sd_xl_single_file.safetensors"), Dtype::F32);
}

#[test]
fn sdxl_layout_single_file_f16() {
    check("sdxl3", &fixture("unet").join("sdxl3/sd_xl_single_file.safetensors"), Dtype::F16);
}

#[test]
fn other_head_counts_bf16_weights_f32() {
    check("heads", &fixture("unet").join("heads/unet"), Dtype::F32);
}

#[test]
fn other_head_counts_bf16_weights_f16() {
    check("heads", &fixture("unet").join("heads/unet"), Dtype::F16);
}

/// Head counts (2 and 8) and norm groups (8) off SDXL's conventions cannot be read from shapes:
/// the single file is loaded with the config given explicitly.
fn heads_single_file(dtype: Dtype) {
    let path = fixture("unet").join("heads/sd_xl_single_file.safetensors");
    let config = UNetConfig::from_file(&fixture("unet").join("heads/unet/config.json")).unwrap();
    check_loaded(&ctx(), "heads", &path, dtype, single_file_unet_checkpoint(&ctx(), &path, config, dtype).unwrap());
}

#[test]
fn other_head_counts_single_file_with_config_f32() {
    heads_single_file(Dtype::F32);
}

#[test]
fn other_head_counts_single_file_with_config_f16() {
    heads_single_file(Dtype::F16);
}
