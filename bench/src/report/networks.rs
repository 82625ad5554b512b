//! The report's network and kernel figures: SDXL's UNet and VAE (`bench unet`'s and `bench vae`'s
//! measurements, run the report's way), the headline products, and the references beside them,
//! run once the device has let its memory go.

use super::figure::{Figure, Reference, Runs};
use super::{Plan, ReferenceChoice};
use crate::kernels::{dtype_name, headline};
use crate::unet::{diffusers_unet, time_unet, RandomInputs, ReferenceDevice};
use crate::vae::{diffusers_vae, time_whole_decode};
use anyhow::Result;
use std::path::Path;
use vkdiff_networks::{AutoencoderKl, Checkpoint, UNet, UNetConfig, SDXL_BASE_CONFIG, SDXL_VAE_CONFIG};
use vkdiff_runtime::{Context, Dtype};

/// The reference a figure waits for, run after the device is released.
pub enum Job {
    /// diffusers' ControlNet + IP-Adapter pipeline; `configs` its models' configs as JSON.
    Workflow {
        configs: String,
        size: usize,
        steps_timed: usize,
        steps: usize,
        dtype: Dtype,
    },
    Unet {
        config: String,
        latent: usize,
        batch: usize,
        dtype: Dtype,
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

const KERNELS_REFERENCE: &str = include_str!("../../../tools/kernels_reference.py");
const WORKFLOW_REFERENCE: &str = include_str!("../../../tools/workflow_reference.py");

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
            Some(config) => Job::Unet { config, latent: plan.network_size / 8, batch: 2, dtype },
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
    Ok(headline(ctx, dtype, plan.runs)?
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

/// Runs each figure's reference (the device released: a CPU reference needs the memory) and
/// writes it into the figure.
pub fn references(plan: &Plan, jobs: Vec<(Figure, Job)>) -> Vec<Figure> {
    let device = match plan.reference {
        ReferenceChoice::None => None,
        ReferenceChoice::Cpu => Some(ReferenceDevice::Cpu),
        ReferenceChoice::Cuda => Some(ReferenceDevice::Cuda),
    };
    let mut kernels: Option<Result<serde_json::Value, String>> = None;
    jobs.into_iter()
        .map(|(mut figure, job)| {
            figure.reference = match (device, job) {
                // The peer runs on vkdiff's own Vulkan device, whatever device diffusers takes.
                (_, Job::Peer { file, size, steps }) => super::peer::sdcpp(&file, size, steps, plan.peer_timeout),
                (_, Job::Measured(reference)) => reference,
                (None, _) => Reference::Missing { why: "not asked for (--reference-device none)".into() },
                (_, Job::None(why)) => Reference::Missing { why },
                (Some(d), Job::Workflow { configs, size, steps_timed, steps, dtype }) => {
                    eprintln!("report: diffusers' pipeline for {}", figure.label);
                    let mut args = [size, steps_timed, steps, plan.runs].map(|n| n.to_string()).to_vec();
                    if d == ReferenceDevice::Cuda {
                        args.extend(["cuda".into(), dtype_name(dtype).into()]);
                    }
                    let run = crate::cpu_reference::run_python_reference(WORKFLOW_REFERENCE, args, Some(&configs));
                    measured(run.map(|v| {
                        let times =
                            v["times"].as_array().map_or(vec![], |a| a.iter().filter_map(|x| x.as_f64()).collect());
                        (times, crate::cpu_reference::label(&v))
                    }))
                }
                (Some(d), Job::Unet { config, latent, batch, dtype }) => {
                    eprintln!("report: diffusers' UNet for {}", figure.label);
                    let cuda = (d == ReferenceDevice::Cuda).then_some(dtype);
                    measured(diffusers_unet(&config, latent, batch, plan.runs, cuda).map(|r| (r.times_ms, r.what)))
                }
                (Some(d), Job::Vae { config, size, dtype }) => {
                    eprintln!("report: diffusers' VAE for {}", figure.label);
                    let dtype = if d == ReferenceDevice::Cpu { Dtype::F32 } else { dtype };
                    measured(diffusers_vae(&config, size, plan.runs, d, dtype).map(|r| (r.times, r.what)))
                }
                (Some(d), Job::Kernel { id, dtype }) => {
                    let all = kernels.get_or_insert_with(|| {
                        eprintln!("report: torch's kernels");
                        let mut args = vec![plan.runs.to_string()];
                        if d == ReferenceDevice::Cuda {
                            args.extend(["cuda".into(), dtype_name(dtype).into()]);
                        }
                        crate::cpu_reference::run_python_reference(KERNELS_REFERENCE, args, None)
                    });
                    measured(all.clone().map(|v| {
                        let rates = v[id].as_array().map_or(vec![], |a| a.iter().filter_map(|x| x.as_f64()).collect());
                        let what = format!(
                            "torch {}, {}",
                            v["torch"].as_str().unwrap_or("?"),
                            v["where"].as_str().unwrap_or("?")
                        );
                        (rates, what)
                    }))
                }
            };
            figure
        })
        .collect()
}

/// The median of a reference's runs, or why it could not run.
fn measured(result: std::result::Result<(Vec<f64>, String), String>) -> Reference {
    match result.map(|(values, what)| (Runs::of(&values), what)) {
        Ok((Some(runs), what)) => Reference::Measured { value: runs.median, what },
        Ok((None, _)) => Reference::Missing { why: "the reference printed no timings".into() },
        Err(why) => Reference::Missing { why },
    }
}
