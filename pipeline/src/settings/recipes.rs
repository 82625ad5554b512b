//! The few-step distillations and the settings each works only with, as their model cards give
//! them: a LoRA or UNet is recognised by its file or repository name, and a run outside its
//! recipe gets one warning line naming it (SDXL-Lightning under another sampler gives "very bad
//! results", stable-diffusion.cpp #198).

use crate::schedulers::{PredictionType, SamplerKind, SchedulerConfig, TimestepSpacing};
use crate::settings::models::{recorded_path, ModelSettings};
use crate::settings::names::timesteps_text;
use crate::settings::sampling::Sampling;
use crate::Result;
use std::path::Path;

/// One distillation's recipe.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Recipe {
    /// Its name as a warning gives it.
    pub name: &'static str,
    pub samplers: &'static [SamplerKind],
    /// None: the sampler picks its own timesteps (LCM, TCD).
    pub spacing: Option<TimestepSpacing>,
    /// The guidance scales it was distilled for, inclusive; at most 1 runs without a negative pass.
    pub cfg: (f32, f32),
    /// Timesteps it was distilled at (DMD2, Hyper-SD's one-step UNet), given as `--timesteps`.
    pub timesteps: Option<&'static [u32]>,
    pub prediction: PredictionType,
}

const NO_CFG: (f32, f32) = (0.0, 1.0);

const fn recipe(name: &'static str, samplers: &'static [SamplerKind], spacing: Option<TimestepSpacing>) -> Recipe {
    Recipe { name, samplers, spacing, cfg: NO_CFG, timesteps: None, prediction: PredictionType::Epsilon }
}

const TRAILING: Option<TimestepSpacing> = Some(TimestepSpacing::Trailing);
const LIGHTNING: Recipe = recipe("SDXL-Lightning", &[SamplerKind::Euler], TRAILING);
const HYPER: Recipe = recipe("Hyper-SD", &[SamplerKind::Ddim, SamplerKind::Tcd], TRAILING);
const DMD2_4: &[u32] = &[999, 749, 499, 249];

/// The recipe of a model file or folder, from its name (or its Hugging Face repository's).
pub fn recipe_of(path: &Path) -> Option<Recipe> {
    let recorded = recorded_path(path).to_ascii_lowercase().replace('_', "-");
    let has = |part: &str| recorded.contains(part);
    Some(if has("sdxl-lightning") && has("1step-unet-x0") {
        Recipe { prediction: PredictionType::Sample, ..LIGHTNING }
    } else if has("sdxl-lightning") {
        LIGHTNING
    } else if has("hyper-sdxl-1step-unet") {
        Recipe { samplers: &[SamplerKind::Lcm], spacing: None, timesteps: Some(&[800]), ..HYPER }
    } else if has("hyper-sdxl") && has("cfg") {
        Recipe { name: "Hyper-SD (CFG-preserving)", samplers: &[SamplerKind::Ddim], cfg: (5.0, 8.0), ..HYPER }
    } else if has("hyper-sdxl") {
        HYPER
    } else if has("lcm-lora-sdxl") {
        Recipe { cfg: (1.0, 2.0), ..recipe("LCM-LoRA", &[SamplerKind::Lcm], None) }
    } else if has("tcd-sdxl") {
        recipe("TCD", &[SamplerKind::Tcd], None)
    } else if has("dmd2-sdxl-4step") {
        Recipe { timesteps: Some(DMD2_4), ..recipe("DMD2 (4 steps)", &[SamplerKind::Lcm], None) }
    } else if has("dmd2-sdxl-1step") {
        Recipe { timesteps: Some(&[399]), ..recipe("DMD2 (1 step)", &[SamplerKind::Lcm], None) }
    } else if has("sdxl-turbo") {
        recipe("SDXL-Turbo", &[SamplerKind::EulerAncestral, SamplerKind::Euler], TRAILING)
    } else {
        return None;
    })
}

impl Recipe {
    /// The flags that run it.
    pub fn flags(&self) -> String {
        let names: Vec<String> = self.samplers.iter().map(|s| s.to_string()).collect();
        let mut flags = vec![format!("--sampler {}", names.join("|"))];
        flags.extend(self.spacing.map(|s| format!("--timestep-spacing {s}")));
        flags.extend(self.timesteps.map(|t| format!("--timesteps {}", timesteps_text(t))));
        if self.prediction != PredictionType::Epsilon {
            flags.push(format!("--prediction-type {}", self.prediction));
        }
        let (low, high) = self.cfg;
        flags.push(if self.cfg == NO_CFG { "--cfg 0".to_string() } else { format!("--cfg {low}–{high}") });
        flags.join(" ")
    }

    /// Where `sampling` on the model's scheduler `config` leaves the recipe, in flags.
    fn departures(&self, sampling: &Sampling, config: &SchedulerConfig) -> Result<Vec<String>> {
        let mut out = Vec::new();
        if !self.samplers.contains(&sampling.sampler) {
            out.push(format!("--sampler {}", sampling.sampler));
        }
        let o = &sampling.schedule;
        if let (Some(want), None, true) = (self.spacing, &o.timesteps, sampling.sampler.reads_spacing()) {
            let spacing = match o.spacing {
                Some(s) => s,
                None => config.spacing(if sampling.sampler == SamplerKind::Ddim { "leading" } else { "linspace" })?,
            };
            if spacing != want || o.karras {
                let karras = if o.karras { " with Karras sigmas" } else { "" };
                out.push(format!("{spacing} timesteps{karras}"));
            }
        }
        if let (Some(want), got) = (self.timesteps, o.timesteps.as_deref()) {
            if got != Some(want) {
                out.push(match got {
                    Some(t) => format!("--timesteps {}", timesteps_text(t)),
                    None => format!("--steps {}", sampling.steps),
                });
            }
        }
        let prediction = match o.prediction {
            Some(p) => p,
            None => config.prediction()?,
        };
        if prediction != self.prediction {
            out.push(format!("prediction type {prediction}"));
        }
        let (low, high) = self.cfg;
        let g = sampling.guidance_scale;
        // Scales at most 1 all run without the negative pass, and mean the same.
        if !(g >= low && g <= high || g <= 1.0 && high <= 1.0) {
            out.push(format!("--cfg {g}"));
        }
        Ok(out)
    }
}

/// One warning line for each distillation among the LoRAs, the swapped UNet and the model that
/// `sampling` runs outside its recipe.
pub fn recipe_warnings(models: &ModelSettings, sampling: &Sampling) -> Result<Vec<String>> {
    let config = SchedulerConfig::of_model(&models.model)?;
    let paths =
        models.loras.iter().map(|l| l.path.as_path()).chain(models.unet.as_deref()).chain([models.model.as_path()]);
    let mut lines = Vec::new();
    for path in paths {
        let Some(recipe) = recipe_of(path) else { continue };
        let departures = recipe.departures(sampling, &config)?;
        if !departures.is_empty() {
            lines.push(format!(
                "warning: {} is {}, made for {}; this run has {}",
                recorded_path(path),
                recipe.name,
                recipe.flags(),
                departures.join(", ")
            ));
        }
    }
    Ok(lines)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::schedulers::ScheduleOptions;

    fn sampling(sampler: SamplerKind, cfg: f32, schedule: ScheduleOptions) -> Sampling {
        Sampling {
            steps: schedule.timesteps.as_ref().map_or(4, Vec::len),
            guidance_scale: cfg,
            sampler,
            schedule,
            width: 1024,
            height: 1024,
            size_conditioning: Default::default(),
            strength: None,
            prompt_syntax: Default::default(),
        }
    }

    #[test]
    fn distillations_are_known_by_their_published_names_in_any_cache() {
        let cache = "/home/u/.cache/huggingface/hub/models--latent-consistency--lcm-lora-sdxl/snapshots/abc123";
        let names = [
            ("sdxl_lightning_4step_lora.safetensors", "SDXL-Lightning"),
            ("models/unet/sdxl_lightning_8step_unet.safetensors", "SDXL-Lightning"),
            ("Hyper-SDXL-8steps-lora.safetensors", "Hyper-SD"),
            ("Hyper-SDXL-12steps-CFG-lora.safetensors", "Hyper-SD (CFG-preserving)"),
            (&format!("{cache}/pytorch_lora_weights.safetensors"), "LCM-LoRA"),
            ("loras/lcm-lora-sdxl.safetensors", "LCM-LoRA"),
            ("/hub/models--h1t--TCD-SDXL-LoRA/snapshots/0f3a/pytorch_lora_weights.safetensors", "TCD"),
            ("dmd2_sdxl_4step_lora_fp16.safetensors", "DMD2 (4 steps)"),
            ("dmd2_sdxl_4step_unet_fp16.bin", "DMD2 (4 steps)"),
            ("/models/sdxl-turbo", "SDXL-Turbo"),
        ];
        for (path, name) in names {
            assert_eq!(recipe_of(Path::new(path)).map(|r| r.name), Some(name), "{path}");
        }
        for other in
            ["pytorch_lora_weights.safetensors", "/models/stable-diffusion-xl-base-1.0", "my_style.safetensors"]
        {
            assert_eq!(recipe_of(Path::new(other)), None, "{other}");
        }
        let x0 = recipe_of(Path::new("sdxl_lightning_1step_unet_x0.safetensors")).unwrap();
        assert_eq!(x0.prediction, PredictionType::Sample);
    }

    #[test]
    fn a_run_departs_from_a_recipe_in_the_flags_it_names() {
        let config = SchedulerConfig::sdxl_base();
        let trailing = ScheduleOptions { spacing: Some(TimestepSpacing::Trailing), ..Default::default() };
        let departures = |r: Recipe, s: Sampling| r.departures(&s, &config).unwrap();
        assert_eq!(departures(LIGHTNING, sampling(SamplerKind::Euler, 0.0, trailing.clone())), Vec::<String>::new());
        assert_eq!(
            departures(LIGHTNING, sampling(SamplerKind::Euler, 5.0, ScheduleOptions::default())),
            ["leading timesteps", "--cfg 5"]
        );
        let dmd2 = recipe_of(Path::new("dmd2_sdxl_4step_lora_fp16.safetensors")).unwrap();
        let dmd2_steps = ScheduleOptions { timesteps: Some(DMD2_4.to_vec()), ..Default::default() };
        assert_eq!(departures(dmd2, sampling(SamplerKind::Lcm, 1.0, dmd2_steps)), Vec::<String>::new());
        assert_eq!(departures(dmd2, sampling(SamplerKind::Lcm, 0.0, ScheduleOptions::default())), ["--steps 4"]);
        // TCD picks its own timesteps: Hyper-SD's trailing spacing is not asked of it.
        let hyper = recipe_of(Path::new("Hyper-SDXL-4steps-lora.safetensors")).unwrap();
        assert_eq!(
            departures(hyper, sampling(SamplerKind::Tcd, 0.0, ScheduleOptions::default())),
            Vec::<String>::new()
        );
        let cfg = recipe_of(Path::new("Hyper-SDXL-8steps-CFG-lora.safetensors")).unwrap();
        assert_eq!(departures(cfg, sampling(SamplerKind::Ddim, 0.0, trailing)), ["--cfg 0"]);
        assert_eq!(LIGHTNING.flags(), "--sampler euler --timestep-spacing trailing --cfg 0");
    }
}
