//! The paper's image as `vkdiff dataset` makes it (scene, control image, guides, the steps with
//! ControlNet, IP-Adapter and merged LoRAs, VAE, PNG and annotations written), and the paper's
//! ablation (its Table 4: the workflow without each of its parts), timed image by image.

use super::figure::{Figure, Reference, Runs};
use super::Plan;
use crate::dataset::{make_set, model_settings, paper_set, random_workflow};
use crate::random_models::style_images;
use crate::step_rate::with_untimed_steps;
use anyhow::Result;
use std::mem::take;
use std::time::Duration;
use vkdiff_dataset::StageTimes;
use vkdiff_lora::LoraFile;
use vkdiff_pipeline::{
    ControlNetSettings, IpAdapterSettings, ModelSettings, RgbImage, TimestepSpacing, WorkflowModels,
};
use vkdiff_runtime::Context;

/// The workflow loaded once, with its LoRAs' files kept so that the ablation can merge subsets.
pub struct Workflow {
    pub models: WorkflowModels,
    loras: Vec<(LoraFile, f32)>,
}

impl Workflow {
    /// Random full-size weights, or the models `user` names (their LoRAs merged here).
    pub fn load(ctx: &Context, plan: &Plan, user: Option<&ModelSettings>) -> Result<Workflow> {
        let Some(user) = user else {
            let random = random_workflow(ctx, plan.dtype, 32)?;
            return Ok(Workflow { models: random.models, loras: random.loras });
        };
        let mut unmerged = user.clone();
        unmerged.loras.clear();
        let mut models = WorkflowModels::load(ctx, &unmerged, &mut |line| eprintln!("{line}"))?;
        models.settings = user.clone();
        let loras =
            user.loras.iter().map(|l| Ok((LoraFile::open(&l.path)?, l.strength))).collect::<Result<Vec<_>>>()?;
        let mut workflow = Workflow { models, loras };
        workflow.merge(&[true; 8])?;
        Ok(workflow)
    }

    /// Merges the LoRAs `on` selects (by index), restoring the others.
    fn merge(&mut self, on: &[bool]) -> Result<()> {
        let refs: Vec<(&LoraFile, f32)> =
            self.loras.iter().zip(on).filter(|(_, &on)| on).map(|((f, s), _)| (f, *s)).collect();
        self.models.sdxl.set_loras(&refs)?;
        Ok(())
    }
}

/// One image made as a set of one: its wall time, its set's once-per-set setup, its stages.
#[derive(Debug, PartialEq)]
struct ImageRun {
    /// What a further image of a set costs: the wall time without the set's setup, with the
    /// steps not timed added at the step rate.
    per_image: f64,
    /// What the set of one cost, its setup included (steps counted the same way).
    whole: f64,
    /// Each stage as it was timed (the steps not run at the step rate): the scene and the
    /// writing run on threads of their own beside the denoiser, so the stages need not add up
    /// to the image, and nothing is left to be "the rest" by subtraction.
    parts: Vec<(String, f64)>,
}

impl ImageRun {
    /// From a set of one's wall time and its stages, with the steps up to `total_steps` not run
    /// counted at the step rate (`step_rate`).
    fn of(wall: Duration, t: &StageTimes, total_steps: usize) -> Result<ImageRun> {
        let secs = Duration::as_secs_f64;
        let steps: Vec<f64> = t.steps.iter().map(secs).collect();
        let ran = secs(&wall) - secs(&t.setup);
        let per_image = with_untimed_steps(ran, &steps, total_steps).map_err(anyhow::Error::msg)?;
        let parts = [
            ("scene (its own thread)", secs(&t.scene)),
            ("guides", secs(&t.guides)),
            ("denoise", secs(&t.denoise()) + per_image - ran),
            ("VAE", secs(&t.vae)),
            ("writing (its own thread)", secs(&t.write)),
            ("once per set (prompt, styles, recording)", secs(&t.setup)),
        ];
        let parts = parts.into_iter().map(|(name, v)| (name.to_string(), v)).collect();
        Ok(ImageRun { per_image, whole: per_image + secs(&t.setup), parts })
    }
}

/// How a figure's image is sampled: the paper's steps with guidance, or SDXL-Lightning's recipe
/// (Euler on trailing timesteps, no guidance: one UNet row a step).
#[derive(Clone, Copy)]
struct Steps {
    total: usize,
    timed: usize,
    lightning: bool,
}

impl Steps {
    fn paper(plan: &Plan) -> Steps {
        Steps { total: plan.steps, timed: plan.steps_timed, lightning: false }
    }

    fn lightning(plan: &Plan) -> Steps {
        Steps { total: FEW_STEPS, timed: FEW_STEPS.min(plan.steps_timed), lightning: true }
    }

    fn note(&self) -> Option<String> {
        (self.timed < self.total).then(|| {
            format!(
                "{} of the {} steps timed, the others counted at the median of the timed steps after the first",
                self.timed, self.total
            )
        })
    }
}

/// The few-step row's steps, and its id.
const FEW_STEPS: usize = 4;
pub const FEW_STEP_ID: &str = "image_4_steps";

fn image_run(models: &mut WorkflowModels, plan: &Plan, steps: Steps, styles: &[Vec<RgbImage>]) -> Result<ImageRun> {
    let mut settings = paper_set(plan.image_size, 1, 1, steps.timed, &models.settings);
    if steps.lightning {
        settings.sampling.guidance_scale = 0.0;
        settings.sampling.schedule.spacing = Some(TimestepSpacing::Trailing);
    }
    let (report, wall) = make_set(models, &settings, styles, 1, true)?;
    ImageRun::of(wall, &report.times, steps.total)
}

/// `plan.runs` images after a warm-up image: the figure.
fn image_figure(
    models: &mut WorkflowModels,
    plan: &Plan,
    steps: Steps,
    ctx: &Context,
    id: &str,
    label: String,
) -> Result<Figure> {
    let styles = if models.style.is_some() { vec![style_images().to_vec()] } else { Vec::new() };
    ctx.reset_peak();
    let first = if plan.warm_up { Some(image_run(models, plan, steps, &styles)?.whole) } else { None };
    let runs: Vec<ImageRun> = (0..plan.runs).map(|_| image_run(models, plan, steps, &styles)).collect::<Result<_>>()?;
    let values: Vec<f64> = runs.iter().map(|r| r.per_image).collect();
    let stats = Runs::of(&values).expect("at least one run");
    // The stages of the run nearest the median.
    let middle =
        runs.iter().min_by(|a, b| (a.per_image - stats.median).abs().total_cmp(&(b.per_image - stats.median).abs()));
    Ok(Figure {
        id: id.into(),
        group: if id == "image" || id == FEW_STEP_ID { "image".into() } else { "ablation".into() },
        label,
        unit: "s".into(),
        higher_is_better: false,
        first_run: first.or(runs.first().map(|r| r.whole)),
        peak_mib: Some(ctx.peak_bytes() as f64 / (1 << 20) as f64),
        parts: middle.map(|r| r.parts.clone()).unwrap_or_default(),
        note: steps.note(),
        peak_share: None,
        runs: stats,
        reference: Reference::Missing { why: String::new() },
    })
}

/// What the workflow holds, for the figure's label.
fn describe(models: &WorkflowModels) -> String {
    let mut parts = vec!["SDXL".to_string()];
    if !models.controlnets.is_empty() {
        parts.push("depth ControlNet".into());
    }
    if models.style.is_some() {
        parts.push("IP-Adapter (2 style images)".into());
    }
    let loras = models.settings.loras.len();
    if loras > 0 {
        parts.push(format!("{loras} LoRA{} merged", if loras > 1 { "s" } else { "" }));
    }
    parts.join(" + ")
}

/// The paper's image: the whole workflow.
pub fn paper_image(workflow: &mut Workflow, plan: &Plan, ctx: &Context) -> Result<Figure> {
    let label =
        format!("the paper's image, {}², {} steps: {}", plan.image_size, plan.steps, describe(&workflow.models));
    image_figure(&mut workflow.models, plan, Steps::paper(plan), ctx, "image", label)
}

/// The paper's image under SDXL-Lightning's 4-step recipe (Euler, trailing timesteps, guidance
/// 0): what a distilled UNet or LoRA of the same architecture makes of the same workflow.
pub fn few_step_image(workflow: &mut Workflow, plan: &Plan, ctx: &Context) -> Result<Figure> {
    let label = format!(
        "the paper's image, {}², {FEW_STEPS} steps (Lightning's recipe: Euler, trailing, no guidance): {}",
        plan.image_size,
        describe(&workflow.models)
    );
    image_figure(&mut workflow.models, plan, Steps::lightning(plan), ctx, FEW_STEP_ID, label)
}

/// One row of the paper's ablation (its Table 4): which parts of the workflow run.
struct Variant {
    id: &'static str,
    name: &'static str,
    controlnet: bool,
    ip_adapter: bool,
    loras: [bool; 2],
}

const ABLATION: [Variant; 8] = [
    Variant {
        id: "ablation.bsd",
        name: "BSD (SDXL, text only)",
        controlnet: false,
        ip_adapter: false,
        loras: [false; 2],
    },
    Variant { id: "ablation.cnet", name: "+CNET", controlnet: true, ip_adapter: false, loras: [false; 2] },
    Variant { id: "ablation.ip", name: "+IP", controlnet: true, ip_adapter: true, loras: [false; 2] },
    Variant { id: "ablation.l1", name: "+L1", controlnet: true, ip_adapter: false, loras: [true, false] },
    Variant { id: "ablation.l2", name: "+L2", controlnet: true, ip_adapter: false, loras: [false, true] },
    Variant { id: "ablation.ip_l1", name: "+IP+L1", controlnet: true, ip_adapter: true, loras: [true, false] },
    Variant { id: "ablation.ip_l2", name: "+IP+L2", controlnet: true, ip_adapter: true, loras: [false, true] },
    Variant { id: "ablation.l1_l2", name: "+L1+L2", controlnet: true, ip_adapter: false, loras: [true, true] },
];

/// The ablation's variants the loaded workflow can make (a LoRA it lacks drops its rows), each
/// timed as the paper's image is; the workflow is whole again after.
pub fn ablation(workflow: &mut Workflow, plan: &Plan, ctx: &Context) -> Result<Vec<Figure>> {
    let m = &mut workflow.models;
    let take_controlnets = |m: &mut WorkflowModels| (take(&mut m.controlnets), take(&mut m.settings.controlnets));
    let mut controlnet = take_controlnets(m);
    let mut style = (m.style.take(), m.settings.ip_adapter.take());
    let all_loras = m.settings.loras.clone();
    let mut figures = Vec::new();
    for v in &ABLATION {
        let wants_lora = v.loras.iter().enumerate().any(|(k, &on)| on && k >= workflow.loras.len());
        if wants_lora || (v.controlnet && controlnet.0.is_empty()) || (v.ip_adapter && style.0.is_none()) {
            continue;
        }
        let m = &mut workflow.models;
        if v.controlnet {
            (m.controlnets, m.settings.controlnets) = take(&mut controlnet);
        }
        if v.ip_adapter {
            (m.style, m.settings.ip_adapter) = (style.0.take(), style.1.take());
        }
        m.settings.loras = all_loras.iter().zip(v.loras).filter(|(_, on)| *on).map(|(l, _)| l.clone()).collect();
        workflow.merge(&v.loras)?;
        eprintln!("report: ablation {}", v.name);
        let label = format!("ablation {}: {}", v.name, describe(&workflow.models));
        let figure = image_figure(&mut workflow.models, plan, Steps::paper(plan), ctx, v.id, label);
        let m = &mut workflow.models;
        if v.controlnet {
            controlnet = take_controlnets(m);
        }
        if v.ip_adapter {
            style = (m.style.take(), m.settings.ip_adapter.take());
        }
        figures.push(figure?);
    }
    let m = &mut workflow.models;
    (m.controlnets, m.settings.controlnets) = controlnet;
    (m.style, m.settings.ip_adapter) = style;
    m.settings.loras = all_loras;
    workflow.merge(&[true; 8])?;
    Ok(figures)
}

/// The settings `bench report` gives user models: the paper's guide strengths, as the random
/// workflow has them.
pub fn user_settings(plan: &Plan, guides: &super::UserModels) -> ModelSettings {
    let paper = model_settings(plan.dtype, &[]);
    let controlnets = (guides.controlnet.iter().zip(paper.controlnets))
        .map(|(model, c)| ControlNetSettings { model: model.clone(), ..c })
        .collect();
    let ip_adapter = match (&guides.ip_adapter, &guides.image_encoder, paper.ip_adapter) {
        (Some(adapter), Some(encoder), Some(ip)) => {
            Some(IpAdapterSettings { adapter: adapter.clone(), encoder: encoder.clone(), ..ip })
        }
        _ => None,
    };
    ModelSettings {
        model: guides.model.clone(),
        unet: guides.unet.clone(),
        controlnets,
        ip_adapter,
        loras: guides.loras.clone(),
        ..paper
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_image_is_its_measured_stages_with_the_untimed_steps_at_the_step_rate() {
        let s = Duration::from_secs_f64;
        let times = StageTimes {
            scene: s(1.0),
            setup: s(2.0),
            guides: s(0.5),
            steps: vec![s(4.0), s(1.5)],
            vae: s(3.0),
            write: s(0.25),
            waiting: s(1.0),
        };
        // 18 s ran beside the setup; 28 steps more at the second step's 1.5 s.
        let run = ImageRun::of(s(20.0), &times, 30).unwrap();
        let parts = [
            ("scene (its own thread)", 1.0),
            ("guides", 0.5),
            ("denoise", 5.5 + 28.0 * 1.5),
            ("VAE", 3.0),
            ("writing (its own thread)", 0.25),
            ("once per set (prompt, styles, recording)", 2.0),
        ];
        let parts = parts.map(|(n, v)| (n.to_string(), v)).to_vec();
        assert_eq!(run, ImageRun { per_image: 18.0 + 42.0, whole: 62.0, parts });
        assert!(ImageRun::of(s(20.0), &StageTimes { steps: vec![s(4.0)], ..times }, 30).is_err());
    }

    #[test]
    fn only_an_image_with_untimed_steps_says_how_they_were_counted() {
        let note = Steps { total: 30, timed: 2, lightning: false }.note().unwrap();
        assert!(note.starts_with("2 of the 30 steps timed") && note.contains("median"), "{note}");
        assert_eq!(Steps { total: 4, timed: 4, lightning: true }.note(), None);
    }
}
