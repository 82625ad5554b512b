//! The report's network and kernel figures: SDXL's UNet and VAE (`bench unet`'s and `bench vae`'s
//! measurements, run the report's way), the headline products, and the reference job each waits
//! for (`references.rs` runs them once the device has let its memory go).

use super::figure::{Figure, Reference, Runs};
use super::Plan;
use crate::kernels::{dtype_name, headline};
use crate::unet::{time_unet, RandomInputs};
use crate::vae::time_whole_decode;
use anyhow::Result;
use std::path::Path;
use vkdiff_networks::{AutoencoderKl, Checkpoint, UNet, UNetConfig, SDXL_BASE_CONFIG, SDXL_VAE_CONFIG};
use vkdiff_runtime::{Context, Dtype};

/// The reference a figure waits for, run after the device is released.
pub enum Job {
    /// diffusers' ControlNet + IP-Adapter pipeline; `configs` its models' configs as JSON;
    /// `warm_up` whether it makes an untimed image first, as vkdiff did.
    Workflow {
        configs: String,
        size: usize,
        steps_timed: usize,
        steps: usize,
        dtype: Dtype,
        warm_up: bool,
    },
    /// diffusers' UNet; `warm_up` as for the workflow.
    Unet {
        config: String,
        latent: usize,
        batch: usize,
        dtype: Dtype,
        warm_up: bool,
    },
    Vae {
        config: String,
        size: usize,
        dtype: Dtype,
    },
    Kernel {
        id: &'static str,
        dtype: Dtype,
    },
    /// A reference vkdiff measured itself in this run (the 4-step image's: the 30-step one).
    Measured(Reference),
    /// stable-diffusion.cpp on the same device, from the file vkdiff timed (see `peer.rs`).
    Peer {
        file: super::peer::PeerFile,
        size: usize,
        steps: usize,
    },
    None(String),
}

/// The configs diffusers' pipeline is built from: SDXL base's with its depth ControlNet, or those
/// of a user's diffusers folders (None for single files or without a ControlNet); `user` is the
/// user's ControlNet where `model` is given. With `ip_adapter`, the pipeline adds one.
pub fn workflow_configs(model: Option<&Path>, user: Option<Option<&Path>>, ip_adapter: bool) -> Option<String> {
    let controlnet = user.flatten();
    let read = |path: &Path| {
        std::fs::read_to_string(path).ok().and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
    };
    let builtin = |text: &str| serde_json::from_str::<serde_json::Value>(text).ok();
    let (unet, vae, scheduler, control) = match (model, controlnet) {
        (None, _) => (
            builtin(SDXL_BASE_CONFIG)?,
            builtin(SDXL_VAE_CONFIG)?,
            builtin(vkdiff_pipeline::SDXL_SCHEDULER_CONFIG)?,
            builtin(vkdiff_networks::SDXL_CONTROLNET_CONFIG)?,
        ),
        (Some(m), Some(c)) => (
            read(&m.join("unet/config.json"))?,
            read(&m.join("vae/config.json"))?,
            read(&m.join("scheduler/scheduler_config.json"))?,
            read(&c.join("config.json"))?,
        ),
        (Some(_), None) => return None,
    };
    let configs = serde_json::json!({
        "unet": unet, "controlnet": control, "vae": vae, "scheduler": scheduler, "ip_adapter": ip_adapter,
    });
    Some(configs.to_string())
}

fn mib(bytes: u64) -> f64 {
    bytes as f64 / (1 << 20) as f64
}

fn precisions(plan: &Plan) -> Vec<Dtype> {
    if plan.quick {
        vec![Dtype::F16]
    } else {
        vec![Dtype::F16, Dtype::F32]
    }
}

/// A diffusers config beside a user's model (its folder's `unet/` or `vae/`), for the reference.
fn user_config(model: &Path, part: &str) -> Option<String> {
    std::fs::read_to_string(model.join(part).join("config.json")).ok()
}

/// SDXL's UNet, batch 2 (one guided step), at the suite's size, in f16 (and f32 in the full suite).
pub fn unet(ctx: &Context, plan: &Plan, model: Option<&Path>) -> Result<Vec<(Figure, Job)>> {
    let mut out = Vec::new();
    for dtype in precisions(plan) {
        eprintln!("report: SDXL UNet {}² batch 2 {}", plan.network_size, dtype_name(dtype));
        let (config, ckpt) = match model {
            Some(path) => vkdiff_networks::unet_checkpoint(ctx, path, dtype)?,
            None => (UNetConfig::sdxl_base(), Checkpoint::random(ctx, dtype, 0)),
        };
        let unet = UNet::load(&config, &ckpt)?;
        ctx.reset_peak();
        let inputs = RandomInputs::new(ctx, &config, dtype, 2, plan.network_size)?;
        let timed = time_unet(&unet, &inputs.inputs(), plan.warm_up, plan.runs)?;
        let runs = Runs::of(&timed.seconds.iter().map(|s| s * 1e3).collect::<Vec<_>>()).expect("runs");
        let flops_per_s = timed.flops / (runs.median / 1e3);
        let figure = Figure {
            id: format!("unet.{}", dtype_name(dtype)),
            group: "unet".into(),
            label: format!("SDXL UNet {}², batch 2, {}", plan.network_size, dtype_name(dtype)),
            unit: "ms".into(),
            higher_is_better: false,
            first_run: Some(timed.first_s * 1e3),
            peak_mib: Some(mib(ctx.peak_bytes())),
            parts: vec![],
            note: Some(format!("{} of products", crate::unet::rate(flops_per_s / 1e12))),
            peak_share: crate::peaks::matrix_peak(ctx).map(|p| flops_per_s / p),
            runs,
            reference: Reference::Missing { why: String::new() },
        };
        let job = match model.map_or(Some(SDXL_BASE_CONFIG.to_string()), |m| user_config(m, "unet")) {
            Some(config) => Job::Unet { config, latent: plan.network_size / 8, batch: 2, dtype, warm_up: plan.warm_up },
            None => Job::None("a single-file model has no diffusers config for the reference".into()),
        };
        out.push((figure, job));
    }
    Ok(out)
}

/// SDXL's VAE, one whole decode at the suite's size: f32 (SDXL's own VAE) and f16 (the fp16-fix
/// VAE's config); a user's VAE in the precision its config allows.
pub fn vae(ctx: &Context, plan: &Plan, model: Option<&Path>) -> Result<Vec<(Figure, Job)>> {
    let mut out = Vec::new();
    let wanted = if plan.quick { vec![Dtype::F16] } else { vec![Dtype::F32, Dtype::F16] };
    for dtype in wanted {
        let (vae, config) = match model {
            Some(path) => (AutoencoderKl::load_sdxl(ctx, path, dtype)?, user_config(path, "vae")),
            None => {
                let mut config: serde_json::Value = serde_json::from_str(SDXL_VAE_CONFIG)?;
                config["force_upcast"] = (dtype == Dtype::F32).into();
                let parsed = serde_json::from_value(config.clone())?;
                (AutoencoderKl::load(ctx, parsed, &Checkpoint::random(ctx, dtype, 0))?, Some(config.to_string()))
            }
        };
        let ran = vae.dtype();
        if out.iter().any(|(f, _): &(Figure, Job)| f.id == format!("vae.{}", dtype_name(ran))) {
            continue; // a VAE whose config forces f32 decodes in f32 either way
        }
        eprintln!("report: SDXL VAE decode {}² {}", plan.network_size, dtype_name(ran));
        ctx.reset_peak();
        let (first, times) = time_whole_decode(&vae, plan.network_size, plan.runs)?;
        let fix = if ran == Dtype::F16 && model.is_none() { " (the fp16-fix VAE's config)" } else { "" };
        let figure = Figure {
            id: format!("vae.{}", dtype_name(ran)),
            group: "vae".into(),
            label: format!("SDXL VAE decode {}², {}{fix}", plan.network_size, dtype_name(ran)),
            unit: "s".into(),
            higher_is_better: false,
            first_run: Some(first),
            peak_mib: Some(mib(ctx.peak_bytes())),
            parts: vec![],
            note: None,
            peak_share: None,
            runs: Runs::of(&times).expect("runs"),
            reference: Reference::Missing { why: String::new() },
        };
        let job = match config {
            Some(config) => Job::Vae { config, size: plan.network_size, dtype: ran },
            None => Job::None("a single-file model has no diffusers config for the reference".into()),
        };
        out.push((figure, job));
    }
    Ok(out)
}

/// The headline products in f16 (f32 where the device has no f16): TFLOP/s.
pub fn kernels(ctx: &Context, plan: &Plan) -> Result<Vec<(Figure, Job)>> {
    let dtype = if ctx.info().supports_f16() { Dtype::F16 } else { Dtype::F32 };
    eprintln!("report: kernels in {}", dtype_name(dtype));
    ctx.reset_peak();
    let peak = crate::peaks::matrix_peak(ctx);
    Ok(headline(ctx, dtype, plan.kernel_runs)?
        .into_iter()
        .map(|h| {
            let runs = Runs::of(&h.tflops).expect("runs");
            let figure = Figure {
                id: format!("kernels.{}", h.id),
                group: "kernels".into(),
                label: format!("{} on {}", h.label, crate::peaks::family_label(ctx, dtype)),
                unit: "TFLOP/s".into(),
                higher_is_better: true,
                first_run: Some(h.first_s),
                peak_mib: Some(mib(ctx.peak_bytes())),
                parts: vec![],
                note: None,
                peak_share: peak.map(|p| runs.median * 1e12 / p),
                runs,
                reference: Reference::Missing { why: String::new() },
            };
            (figure, Job::Kernel { id: h.id, dtype })
        })
        .collect())
}
