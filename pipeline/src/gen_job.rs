//! `vkdiff gen`'s one entry: a request checked once, before any model loads (the output files,
//! the prompt's template expanded, the models, the input images, the size the inputs imply, the
//! sampling, the prompts), then run and written atomically: the PNG with its settings and, if
//! asked, the latents, together or not at all.

use crate::error::{Error, Result};
use crate::files::{png_bytes, write_atomic_all};
use crate::schedulers::SchedulerConfig;
use crate::sdxl::{check_control_shape, Sdxl, Timings, WorkflowModels};
use crate::settings::{GenSettings, GuideInputs, PromptTemplate, Wildcards};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use vkdiff_render::control::ControlKind;
use vkdiff_runtime::Context;
use vkdiff_setting::Message;

/// The size without a depth or init image to take it from.
const DEFAULT_SIDE: usize = 1024;
/// img2img's strength when none is given: diffusers' SDXL img2img default.
const DEFAULT_STRENGTH: f64 = 0.3;

/// What `vkdiff gen` is asked for, as given.
pub struct GenRequest {
    /// The models and the image; the sampling's size and strength are set from the fields below.
    pub settings: GenSettings,
    /// The image size; unset, the depth image's (else the init image's, else 1024).
    pub width: Option<usize>,
    pub height: Option<usize>,
    /// img2img's strength (with an init image only); unset, 0.3.
    pub strength: Option<f64>,
    /// The PNG to write.
    pub out: PathBuf,
    /// Where to write the final latents too, if anywhere.
    pub latents_out: Option<PathBuf>,
    /// Replace output files that exist.
    pub replace: bool,
    /// The folder of the wildcard files the prompt's template names (`__soil__`: `soil.txt`).
    pub wildcards: Option<PathBuf>,
}

/// A checked request with its input images read.
pub struct GenJob {
    settings: GenSettings,
    inputs: GuideInputs,
    out: PathBuf,
    latents_out: Option<PathBuf>,
    /// The prompt as given, where it was a template (the settings hold its expansion).
    prompt_template: Option<String>,
}

/// What a run tells as it goes.
pub enum GenEvent<'a> {
    /// A line for the user: what is loading, what a LoRA touched, a prompt that is cut.
    Note(&'a str),
    /// Every model is loaded, in this time.
    Loaded(Duration),
    /// `done` of `total` denoising steps finished.
    Step { done: usize, total: usize },
}

impl GenJob {
    /// Checks everything that can be checked without loading a model, in the order a user
    /// fixes it: output files, model files, input images, then the image settings.
    pub fn new(request: GenRequest) -> Result<GenJob> {
        let GenRequest { mut settings, width, height, strength, out, latents_out, replace, wildcards } = request;
        for (setting, path) in std::iter::once(("out", &out)).chain(latents_out.iter().map(|p| ("latents_out", p))) {
            check_output(setting, path, replace)?;
        }
        if out.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() != Some("png") {
            return Err(Error::Setting(
                Message::setting("out")
                    .then(format!(" {}: the image is written as PNG; give a .png path", out.display())),
            ));
        }
        // The prompt's template, expanded from the seed (the negative prompt is taken as written).
        let template = PromptTemplate::parse(&settings.job.prompt)?;
        let wildcards = Wildcards::load(wildcards.as_deref(), &[&template])?;
        wildcards.check_no_scene(&template)?;
        settings.job.prompt = template.expand(settings.job.seed, &wildcards, None)?.prompt;
        let prompt_template = template.is_template().then(|| template.text().to_string());
        settings.models.check()?;
        let inputs = settings.read_inputs()?;
        // A depth map (else an init image) sets the size unless it is given: the image then lines
        // up with the depth; an init image keeps its size as diffusers' img2img does.
        let given = inputs.controls.values().next().or(inputs.init.as_ref());
        let (default_w, default_h) = given.map_or((DEFAULT_SIDE, DEFAULT_SIDE), |c| (c.width, c.height));
        let sampling = &mut settings.job.sampling;
        sampling.width = width.unwrap_or(default_w);
        sampling.height = height.unwrap_or(default_h);
        sampling.strength = settings.init_image.as_ref().map(|_| strength.unwrap_or(DEFAULT_STRENGTH));
        let sampling = &settings.job.sampling;
        sampling.check(&SchedulerConfig::of_model(&settings.models.model)?)?;
        for prompt in std::iter::once(&settings.job.prompt).chain(&settings.job.negative_prompt) {
            sampling.prompt_syntax.check(prompt)?;
        }
        let multiple = Sdxl::probe_pixel_multiple(&settings.models.model, settings.models.swaps())?;
        sampling.check_size(multiple)?;
        for (&kind, control) in &inputs.controls {
            let setting = if kind == ControlKind::Depth { "depth" } else { "control_image" };
            check_control_shape(setting, control, sampling.width, sampling.height, multiple)?;
        }
        Ok(GenJob { settings, inputs, out, latents_out, prompt_template })
    }

    pub fn settings(&self) -> &GenSettings {
        &self.settings
    }

    /// Loads the models on `ctx`, generates, and writes the files; where the time went.
    pub fn run(&self, ctx: &Context, events: &mut dyn FnMut(GenEvent)) -> Result<Timings> {
        let start = Instant::now();
        let mut models = WorkflowModels::load(ctx, &self.settings.models, &mut |line| events(GenEvent::Note(line)))?;
        events(GenEvent::Loaded(start.elapsed()));
        let job = &self.settings.job;
        let (width, height) = (job.sampling.width, job.sampling.height);
        let vae = models.sdxl.plan_vae(self.settings.models.vae_tiling, 1, width, height)?;
        if let Some(note) = vae.note(width, height) {
            events(GenEvent::Note(&note));
        }
        let prompts = std::iter::once(&job.prompt).chain(&job.negative_prompt);
        for warning in models.sdxl.cut_prompt_warnings(job.sampling.prompt_syntax, prompts) {
            events(GenEvent::Note(&warning));
        }
        // The prompts are encoded once: the encoders' memory goes before the denoiser's comes.
        let start = Instant::now();
        let text = models.sdxl.encode_job(job)?;
        let encoding = start.elapsed();
        models.sdxl.release_text_encoders();
        let guides = models.guides(&self.inputs);
        let mut out = models
            .sdxl
            .text_to_image_encoded(job, &text, &guides, &mut |done, total| events(GenEvent::Step { done, total }))?;
        out.timings.text_encoding = encoding;
        let mut text = self.settings.png_text();
        if let Some(tiling) = vae.tiling {
            text.insert("vae_tile".into(), tiling.tile.to_string());
        }
        if let Some(template) = &self.prompt_template {
            text.insert("prompt_template".into(), template.clone());
        }
        let png = png_bytes(&out.image, &text)?;
        let latents = self
            .latents_out
            .as_ref()
            .map(|_| vkdiff_formats::safetensors_f32_bytes(&[("latents", &out.latent_shape, &out.latents)], &text));
        let mut files = vec![(self.out.as_path(), png.as_slice())];
        files.extend(self.latents_out.as_deref().zip(latents.as_deref()));
        write_atomic_all(&files)?;
        Ok(out.timings)
    }
}

/// An output file's folder must exist, and the file must not unless it may be replaced.
fn check_output(setting: &str, path: &Path, replace: bool) -> Result<()> {
    let parent = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if !parent.is_dir() {
        return Err(Error::Setting(Message::setting(setting).then(format!(
            " {}: folder {} does not exist",
            path.display(),
            parent.display()
        ))));
    }
    if path.exists() && !replace {
        return Err(Error::Setting(
            Message::setting(setting)
                .then(format!(" {} exists; give ", path.display()))
                .and("replace")
                .then(" to replace it"),
        ));
    }
    Ok(())
}
