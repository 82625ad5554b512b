//! What a generation is asked for: the sampling settings a batch shares, SDXL's size
//! conditioning, and one image's prompt and seed; each checked once, before any work.

use crate::error::{Error, Result};
use crate::schedulers::{Sampler, SamplerKind, ScheduleOptions, SchedulerConfig};
use crate::settings::prompt_syntax::PromptSyntax;
use vkdiff_setting::Message;

/// How every image of a run is sampled: the settings a batch shares.
#[derive(Clone, Debug, PartialEq)]
pub struct Sampling {
    /// Denoising steps; with custom timesteps, their count.
    pub steps: usize,
    pub guidance_scale: f32,
    pub sampler: SamplerKind,
    /// Karras σ's, spacing, prediction type, custom timesteps, TCD's γ.
    pub schedule: ScheduleOptions,
    pub width: usize,
    pub height: usize,
    pub size_conditioning: SizeConditioning,
    /// img2img: how much of the schedule runs over the init image (diffusers' `strength`);
    /// `None` starts from noise.
    pub strength: Option<f64>,
    pub prompt_syntax: PromptSyntax,
}

/// SDXL's size micro-conditioning, as diffusers' `original_size`, `crops_coords_top_left` and
/// `target_size` (negative rows get the same, diffusers' default). Unset sizes are the image's.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SizeConditioning {
    /// (width, height) of the imagined source image.
    pub original: Option<(usize, usize)>,
    /// (top, left) of the imagined crop, in diffusers' order.
    pub crop_top_left: (usize, usize),
    /// (width, height).
    pub target: Option<(usize, usize)>,
}

impl Sampling {
    /// The UNet's `time_ids`: original (h, w), crop (top, left), target (h, w).
    pub fn time_ids(&self) -> [f32; 6] {
        let c = &self.size_conditioning;
        let own = (self.width, self.height);
        let ((ow, oh), (top, left), (tw, th)) = (c.original.unwrap_or(own), c.crop_top_left, c.target.unwrap_or(own));
        [oh, ow, top, left, th, tw].map(|v| v as f32)
    }

    /// Classifier-free guidance runs a negative row beside each positive one.
    pub fn guided(&self) -> bool {
        self.guidance_scale > 1.0
    }

    /// What is wrong with the model's scheduler `config`: the guidance scale, the step count, a
    /// noise schedule or option the sampler does not have, a strength that leaves no step.
    pub fn check(&self, config: &SchedulerConfig) -> Result<()> {
        if !self.guidance_scale.is_finite() {
            return Err(Error::Setting(
                Message::setting("guidance_scale").then(format!(" {} is not a number", self.guidance_scale)),
            ));
        }
        match &self.schedule.timesteps {
            Some(timesteps) if timesteps.len() != self.steps => {
                return Err(Error::Setting(
                    Message::setting("steps")
                        .then(format!(" {} with {} ", self.steps, timesteps.len()))
                        .and("timesteps")
                        .then(": give one or the other"),
                ))
            }
            _ => {}
        }
        self.sampler(config)?;
        self.first_step().map(|_| ())
    }

    /// A fresh sampler for one image, on the model's scheduler `config`.
    pub fn sampler(&self, config: &SchedulerConfig) -> Result<Sampler> {
        Sampler::new(self.sampler, config, self.steps, &self.schedule)
    }

    /// The step img2img starts at (diffusers' `get_timesteps`: the last ⌊steps · strength⌋ steps
    /// run); 0 without an init image.
    pub fn first_step(&self) -> Result<usize> {
        let Some(strength) = self.strength else { return Ok(0) };
        if !(strength > 0.0 && strength <= 1.0) {
            return Err(Error::Setting(Message::setting("strength").then(format!(" {strength} must be in (0, 1]"))));
        }
        let run = ((self.steps as f64 * strength) as usize).min(self.steps);
        if run == 0 {
            return Err(Error::Setting(
                Message::text(format!("a strength of {strength} over {} steps runs none of them; raise ", self.steps))
                    .and("steps")
                    .then(" or ")
                    .and("strength"),
            ));
        }
        Ok(self.steps - run)
    }

    /// The size must be a positive multiple of the model's `multiple` ([`crate::Sdxl::pixel_multiple`]).
    pub fn check_size(&self, multiple: usize) -> Result<()> {
        for (setting, v) in [("width", self.width), ("height", self.height)] {
            if v == 0 || !v.is_multiple_of(multiple) {
                return Err(Error::Setting(
                    Message::setting(setting)
                        .then(format!(" {v} must be a positive multiple of {multiple} for this model")),
                ));
            }
        }
        Ok(())
    }

    /// UNet rows per image: 2 with guidance ([negative, positive]), else 1.
    pub fn rows_per_image(&self) -> usize {
        if self.guided() {
            2
        } else {
            1
        }
    }
}

/// One image's settings (the `vkdiff gen` flags).
#[derive(Clone, Debug)]
pub struct TextToImage {
    pub prompt: String,
    /// `None`: zero negative conditioning where the model asks for it (diffusers' default).
    pub negative_prompt: Option<String>,
    pub seed: u64,
    pub sampling: Sampling,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sampling() -> Sampling {
        Sampling {
            steps: 4,
            guidance_scale: 5.0,
            sampler: SamplerKind::Euler,
            schedule: ScheduleOptions::default(),
            width: 64,
            height: 64,
            size_conditioning: SizeConditioning::default(),
            strength: None,
            prompt_syntax: PromptSyntax::default(),
        }
    }

    /// Refusals name settings as data; without a front end's names they read as the fields.
    #[test]
    fn refusals_carry_the_settings_they_name() {
        let named = |s: Sampling| match s.check(&SchedulerConfig::sdxl_base()) {
            Err(Error::Setting(m)) => (m.settings().map(String::from).collect::<Vec<_>>(), m.to_string()),
            other => panic!("{other:?}"),
        };
        let nan = named(Sampling { guidance_scale: f32::NAN, ..sampling() });
        assert_eq!(nan, (vec!["guidance_scale".into()], "guidance_scale NaN is not a number".into()));
        let (names, text) = named(Sampling { strength: Some(0.2), ..sampling() });
        assert_eq!(names, ["steps", "strength"], "{text}");
        assert!(text.ends_with("runs none of them; raise steps or strength"), "{text}");
        assert!(sampling().check(&SchedulerConfig::sdxl_base()).is_ok());
    }
}
