//! The references beside the report's figures, run once the device has let its memory go, each
//! script's output read into its own type: a field it lacks is an error naming the field and the
//! script, never a default.

use super::figure::{Figure, Reference, Runs};
use super::networks::Job;
use super::{Plan, ReferenceChoice};
use crate::cpu_reference::{run_python_reference, script, DiffusersRun, Script};
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
/// writes it into the figure.
pub fn references(plan: &Plan, jobs: Vec<(Figure, Job)>, env: &Environment) -> Vec<Figure> {
    let device = match plan.reference {
        ReferenceChoice::None => None,
        ReferenceChoice::Cpu => Some(ReferenceDevice::Cpu),
        ReferenceChoice::Cuda => Some(ReferenceDevice::Cuda),
    };
    let mut kernels: Option<Result<KernelRates, String>> = None;
    jobs.into_iter()
        .map(|(mut figure, job)| {
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
                    measured(timed.map(|r| (r.times_ms, r.what)))
                }
                (Some(d), Job::Vae { config, size, dtype }) => {
                    eprintln!("report: diffusers' VAE for {}", figure.label);
                    let dtype = if d == ReferenceDevice::Cpu { Dtype::F32 } else { dtype };
                    measured(diffusers_vae(env, &config, size, plan.runs, d, dtype).map(|r| (r.times, r.what)))
                }
                (Some(d), Job::Kernel { id, dtype }) => {
                    let all = kernels.get_or_insert_with(|| {
                        eprintln!("report: torch's kernels");
                        let mut args = vec![plan.runs.to_string()];
                        if d == ReferenceDevice::Cuda {
                            args.extend(["cuda".into(), dtype_name(dtype).into()]);
                        }
                        run_python_reference(env, KERNELS_REFERENCE, args, None)
                    });
                    measured(
                        all.clone()
                            .and_then(|rates| Ok((rates.of(id)?, format!("torch {}, {}", rates.torch, rates.place)))),
                    )
                }
            };
            figure
        })
        .collect()
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
                "torch": "9.1", "diffusers": "9.2", "where": "stub"}"#,
        )
        .unwrap();
        // 28 untimed steps at each image's second step.
        assert_eq!(out.per_image(2, 2, 30), Ok(vec![7.0 + 28.0 * 1.5, 6.0 + 28.0 * 2.0]));
        assert!(out.per_image(1, 2, 30).unwrap_err().contains("2 images for 1 runs"));
        assert!(out.per_image(2, 3, 30).unwrap_err().contains("2 step times for 3 timed steps"));
    }
}
