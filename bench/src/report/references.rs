//! The references beside the report's figures, run once the device has let its memory go, each
//! script's output read into its own type: a field it lacks is an error naming the field and the
//! script, never a default.

use super::figure::{Figure, Reference, Runs};
use super::networks::Job;
use super::{Plan, ReferenceChoice};
use crate::cpu_reference::{run_python_reference, script, Compiled, Conditions, DiffusersRun, Script};
use crate::kernels::dtype_name;
use crate::step_rate::with_untimed_steps;
use crate::unet::{diffusers_unet, ReferenceDevice};
use crate::vae::diffusers_vae;
use serde::Deserialize;
use vkdiff_runtime::{Dtype, Environment};

const KERNELS_REFERENCE: Script = script!("kernels_reference.py");
const WORKFLOW_REFERENCE: Script = script!("workflow_reference.py");

/// `tools/kernels_reference.py`'s TFLOP/s of each timed run, by headline product.
#[derive(Clone, Deserialize)]
struct KernelRates {
    linear: Vec<f64>,
    conv: Vec<f64>,
    attention: Vec<f64>,
    torch: String,
    #[serde(rename = "where")]
    place: String,
    #[serde(flatten)]
    conditions: Conditions,
}

impl KernelRates {
    fn of(&self, id: &str) -> Result<Vec<f64>, String> {
        match id {
            "linear" => Ok(self.linear.clone()),
            "conv" => Ok(self.conv.clone()),
            "attention" => Ok(self.attention.clone()),
            _ => Err(format!("{} times no product `{id}`", KERNELS_REFERENCE.path)),
        }
    }
}

/// `tools/workflow_reference.py`'s timed images.
#[derive(Deserialize)]
struct WorkflowTimes {
    images: Vec<ImageTimes>,
    #[serde(flatten)]
    run: DiffusersRun,
}

/// One image: its seconds, and each of its timed steps' (between the ends of consecutive steps;
/// the first from the call's start).
#[derive(Deserialize)]
struct ImageTimes {
    seconds: f64,
    steps: Vec<f64>,
}

impl WorkflowTimes {
    /// Each image's seconds with its untimed steps at the step rate, as vkdiff's are counted.
    fn per_image(&self, runs: usize, steps_timed: usize, steps: usize) -> Result<Vec<f64>, String> {
        let path = WORKFLOW_REFERENCE.path;
        if self.images.len() != runs {
            return Err(format!("{path} printed {} images for {runs} runs", self.images.len()));
        }
        self.images
            .iter()
            .map(|image| {
                if image.steps.len() != steps_timed {
                    return Err(format!(
                        "{path} printed {} step times for {steps_timed} timed steps",
                        image.steps.len()
                    ));
                }
                with_untimed_steps(image.seconds, &image.steps, steps).map_err(|why| format!("{path}: {why}"))
            })
            .collect()
    }
}

/// Runs each figure's reference (the device released: a CPU reference needs the memory) and
/// writes it into the figure; a network whose reference also ran compiled gets a second row, the
/// same vkdiff figure against the compiled model (`ID.compiled`).
pub fn references(plan: &Plan, jobs: Vec<(Figure, Job)>, env: &Environment) -> Vec<Figure> {
    let device = match plan.reference {
        ReferenceChoice::None => None,
        ReferenceChoice::Cpu => Some(ReferenceDevice::Cpu),
        ReferenceChoice::Cuda => Some(ReferenceDevice::Cuda),
    };
    let mut kernels: Option<Result<KernelRates, String>> = None;
    let mut out = Vec::new();
    for (mut figure, job) in jobs {
        let mut compiled: Option<(Compiled, String, f64)> = None;
        figure.reference = match (device, job) {
            // The peer runs on vkdiff's own Vulkan device, whatever device diffusers takes.
            (_, Job::Peer { file, size, steps }) => super::peer::sdcpp(env, &file, size, steps, plan.peer_timeout),
            (_, Job::Measured(reference)) => reference,
            (None, _) => Reference::Missing { why: "not asked for (--reference-device none)".into() },
            (_, Job::None(why)) => Reference::Missing { why },
            (Some(d), Job::Workflow { configs, size, steps_timed, steps, dtype, warm_up }) => {
                eprintln!("report: diffusers' pipeline for {}", figure.label);
                let mut args = [size, steps_timed, plan.runs, usize::from(warm_up)].map(|n| n.to_string()).to_vec();
                if d == ReferenceDevice::Cuda {
                    args.extend(["cuda".into(), dtype_name(dtype).into()]);
                }
                measured(run_python_reference(env, WORKFLOW_REFERENCE, args, Some(&configs)).and_then(
                    |out: WorkflowTimes| Ok((out.per_image(plan.runs, steps_timed, steps)?, out.run.label())),
                ))
            }
            (Some(d), Job::Unet { config, latent, batch, dtype, warm_up }) => {
                eprintln!("report: diffusers' UNet for {}", figure.label);
                let cuda = (d == ReferenceDevice::Cuda).then_some(dtype);
                let timed = diffusers_unet(env, &config, latent, batch, plan.runs, warm_up, cuda);
                if let Ok(r) = &timed {
                    compiled = Some((r.compiled.clone(), r.what.clone(), 1e3));
                }
                measured(timed.map(|r| (r.times_ms, with_events(r.what, r.gpu_ms.as_deref(), "ms"))))
            }
            (Some(d), Job::Vae { config, size, dtype }) => {
                eprintln!("report: diffusers' VAE for {}", figure.label);
                let dtype = if d == ReferenceDevice::Cpu { Dtype::F32 } else { dtype };
                let timed = diffusers_vae(env, &config, size, plan.runs, d, dtype);
                if let Ok(r) = &timed {
                    compiled = Some((r.compiled.clone(), r.what.clone(), 1.0));
                }
                measured(timed.map(|r| (r.times, with_events(r.what, r.gpu.as_deref(), "s"))))
            }
            (Some(d), Job::Kernel { id, dtype }) => {
                let all = kernels.get_or_insert_with(|| {
                    eprintln!("report: torch's kernels");
                    let mut args = vec![plan.kernel_runs.to_string()];
                    if d == ReferenceDevice::Cuda {
                        args.extend(["cuda".into(), dtype_name(dtype).into()]);
                    }
                    run_python_reference(env, KERNELS_REFERENCE, args, None)
                });
                measured(all.clone().and_then(|rates| {
                    let what = format!("torch {}, {}; {}", rates.torch, rates.place, rates.conditions.label());
                    Ok((rates.of(id)?, what))
                }))
            }
        };
        let twin = compiled.map(|(c, what, scale)| compiled_twin(&figure, &c, &what, scale));
        out.push(figure);
        out.extend(twin);
    }
    out
}

/// `figure` again, against the compiled model: PyTorch at its best, beside the eager row.
fn compiled_twin(figure: &Figure, compiled: &Compiled, what: &str, scale: f64) -> Figure {
    let mut twin = figure.clone();
    twin.id = format!("{}{}", figure.id, super::figure::COMPILED);
    twin.label = format!("{}, against PyTorch compiled", figure.label);
    twin.reference = measured(compiled.samples(scale).map(|values| {
        let events = compiled.gpu.as_ref().map(|g| g.iter().map(|s| s * scale).collect::<Vec<_>>());
        (values, with_events(format!("{}; {what}", compiled.how), events.as_deref(), &figure.unit))
    }));
    twin
}

/// `what`, with the median of the samples' GPU times by CUDA events where there are some.
fn with_events(what: String, gpu: Option<&[f64]>, unit: &str) -> String {
    match gpu.and_then(crate::cpu_reference::median) {
        Some(m) => format!("{what}; GPU time by CUDA events {}", super::figure::show(m, unit)),
        None => what,
    }
}

/// The median of a reference's runs, or why it could not run.
fn measured(result: Result<(Vec<f64>, String), String>) -> Reference {
    match result.map(|(values, what)| (Runs::of(&values), what)) {
        Ok((Some(runs), what)) => Reference::Measured { value: runs.median, what },
        Ok((None, _)) => Reference::Missing { why: "the reference printed no timings".into() },
        Err(why) => Reference::Missing { why },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_headline_product_takes_its_own_rates() {
        let rates = KernelRates {
            linear: vec![1.0],
            conv: vec![2.0, 3.0],
            attention: vec![4.0],
            torch: "9.1".into(),
            place: "stub".into(),
            conditions: Conditions { settings: vec![], sdpa: None, host: "stub".into(), clocks: None },
        };
        assert_eq!(rates.of("linear"), Ok(vec![1.0]));
        assert_eq!(rates.of("conv"), Ok(vec![2.0, 3.0]));
        assert_eq!(rates.of("attention"), Ok(vec![4.0]));
        let why = rates.of("gemm").unwrap_err();
        assert!(why.contains("tools/kernels_reference.py") && why.contains("`gemm`"), "{why}");
    }

    #[test]
    fn each_reference_image_counts_its_untimed_steps_at_its_step_rate() {
        let out: WorkflowTimes = serde_json::from_str(
            r#"{"images": [{"seconds": 7.0, "steps": [4.0, 1.5]}, {"seconds": 6.0, "steps": [3.0, 2.0]}],
                "torch": "9.1", "diffusers": "9.2", "where": "stub", "settings": [], "host": "h", "clocks": null}"#,
        )
        .unwrap();
        // 28 untimed steps at each image's second step.
        assert_eq!(out.per_image(2, 2, 30), Ok(vec![7.0 + 28.0 * 1.5, 6.0 + 28.0 * 2.0]));
        assert!(out.per_image(1, 2, 30).unwrap_err().contains("2 images for 1 runs"));
        assert!(out.per_image(2, 3, 30).unwrap_err().contains("2 step times for 3 timed steps"));
    }

    #[test]
    fn a_compiled_reference_that_did_not_run_says_why_in_its_row() {
        let figure = super::super::figure::test_figure("unet.f16", 100.0, Reference::Missing { why: String::new() });
        let failed = Compiled { wall: None, gpu: None, how: "torch.compile failed: no compiler".into() };
        let twin = compiled_twin(&figure, &failed, "eager", 1e3);
        assert_eq!((twin.id.as_str(), twin.is_compiled_twin()), ("unet.f16.compiled", true));
        assert_eq!(twin.reference, Reference::Missing { why: "torch.compile failed: no compiler".into() });
        let ran = Compiled { wall: Some(vec![0.05, 0.07, 0.06]), gpu: Some(vec![0.04]), how: "graph".into() };
        let twin = compiled_twin(&figure, &ran, "eager", 1e3);
        let what = "graph; eager; GPU time by CUDA events 40.0 ms".to_string();
        assert_eq!(twin.reference, Reference::Measured { value: 60.0, what });
        assert_eq!(twin.speedup(), Some(0.6));
    }
}
