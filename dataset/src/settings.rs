//! A dataset's settings: the scenes (the procedural bed with `vkdiff scene`'s flags, or scenes
//! rendered elsewhere), the images (`vkdiff gen`'s flags), and the per-image variety (prompts,
//! each perhaps a template expanded per image, style-image sets). They are recorded in `dataset.json` under the flag names, so a run with
//! other settings into the same folder is refused naming the flag.

use crate::controls::LabelControls;
use crate::error::{Error, Result};
use crate::regions::{RegionFlags, RegionSettings};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use vkdiff_pipeline::SchedulerConfig;
use vkdiff_pipeline::Sdxl;
use vkdiff_pipeline::{CategorySlots, Expansion, PromptTemplate, Wildcards};
use vkdiff_pipeline::{ModelSettings, Sampling};
use vkdiff_render::control::{ControlDepth, ControlKind};
use vkdiff_render::crops::{centered, centered_window, validate_min_fraction, CropWindow};
use vkdiff_scenes::SceneSource;
use vkdiff_setting::Message;

/// How each scene's frame is cut into images.
#[derive(Clone, Debug, PartialEq)]
pub struct Crops {
    /// Square crops per scene; 0: one image per scene, the whole frame cut to the model's multiple.
    pub count: usize,
    pub size: u32,
    /// An instance stays in a crop when this share of its visible pixels falls inside.
    pub min_fraction: f64,
}

#[derive(Clone, Debug)]
pub struct DatasetSettings {
    /// Scene `k` has seed `seed + k`; image `i` has seed [`crate::image_seed`]`(seed, i)`.
    pub seed: u64,
    /// Scenes.
    pub count: u64,
    pub source: Arc<dyn SceneSource>,
    pub crops: Crops,
    pub control_depth: ControlDepth,
    /// The controls made beside the depth control (`--controls`).
    pub controls: LabelControls,
    /// A prompt and a strength per category (none by default).
    pub regions: RegionSettings,
    /// The diffusion models; None for a render-only set, whose images are the shaded renders.
    pub models: Option<ModelSettings>,
    /// The `--prompt`s, one chosen per image from its seed, then every scene's own prompt
    /// (prompt.txt), which its images take.
    pub prompts: Vec<String>,
    /// How many of `prompts` are the `--prompt`s.
    pub user_prompts: usize,
    /// Each of `prompts` read as a template (a prompt without template syntax is its own
    /// expansion); empty for a render-only set.
    pub templates: Vec<PromptTemplate>,
    /// The wildcard files the templates read (`--wildcards`).
    pub wildcards: Wildcards,
    pub negative_prompt: Option<String>,
    /// Steps, guidance and sampler; the size is the images' (crop size, or the cut frame).
    pub sampling: Sampling,
    /// Style-image sets for the IP-Adapter; one is chosen per image from its seed.
    pub ip_sets: Vec<Vec<PathBuf>>,
}

impl DatasetSettings {
    /// Checks every setting and fixes the image size: crops of `crops.size`, or the frame cut to
    /// sides that are multiples of the model's pixel multiple (`Sdxl::probe_pixel_multiple`;
    /// SDXL's 8 for a render-only set, `models` None, which takes no prompts or styles). `count`
    /// is the procedural bed's scenes, or how many of the rendered scenes (all: None). Every
    /// prompt (a scene's own too) is read as a template, its wildcards from `wildcards`.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        seed: u64,
        count: Option<u64>,
        source: Arc<dyn SceneSource>,
        crops: Crops,
        control_depth: ControlDepth,
        models: Option<ModelSettings>,
        prompts: Vec<String>,
        negative_prompt: Option<String>,
        mut sampling: Sampling,
        ip_sets: Vec<Vec<PathBuf>>,
        wildcards: Option<PathBuf>,
    ) -> Result<DatasetSettings> {
        validate_min_fraction(crops.min_fraction)?;
        let count = match (source.available(), count) {
            (None, count) => count.unwrap_or(1),
            (Some(all), None) => all,
            (Some(all), Some(count)) if count <= all => count,
            (Some(all), Some(count)) => {
                return Err(Error::Setting(
                    Message::setting("count").then(format!(" {count}: ")).and("scenes").then(format!(" holds {all}")),
                ))
            }
        };
        if count == 0 {
            return Err(Error::Setting(Message::setting("count").then(" must be at least 1")));
        }
        if seed.checked_add(count).is_none() {
            return Err(Error::Setting(
                Message::setting("count")
                    .then(format!(" {count} runs past the largest seed from "))
                    .and("seed")
                    .then(format!(" {seed}")),
            ));
        }
        let scene_prompts = distinct((0..count).filter_map(|k| source.scene(k).prompt));
        let (mut templates, mut loaded) = (Vec::new(), Wildcards::default());
        let multiple = match &models {
            Some(models) => {
                let every_scene_has_one = (0..count).all(|k| source.scene(k).prompt.is_some());
                templates = (prompts.iter().chain(&scene_prompts))
                    .map(|p| PromptTemplate::parse(p))
                    .collect::<vkdiff_pipeline::Result<Vec<_>>>()?;
                loaded = Wildcards::load(wildcards.as_deref(), &templates.iter().collect::<Vec<_>>())?;
                let user = &templates[..prompts.len()];
                check_diffusion(models, user, &loaded, every_scene_has_one, &negative_prompt, &sampling, &ip_sets)?;
                Sdxl::probe_pixel_multiple(&models.model, models.swaps())? as u32
            }
            None => {
                check_render_only(&prompts, &negative_prompt, &sampling, &ip_sets, &wildcards)?;
                RENDER_ONLY_MULTIPLE
            }
        };
        let (width, height) = if crops.count > 0 {
            for k in 0..count {
                let scene = source.scene(k);
                let (w, h) = (scene.width, scene.height);
                if crops.size == 0 || crops.size > w.min(h) {
                    let of = scene.name.map_or(String::new(), |n| format!(" of scene {n}"));
                    return Err(Error::Setting(Message::setting("crop_size").then(format!(
                        " {} must lie in [1, {}] to fit the {w}×{h} frame{of}",
                        crops.size,
                        w.min(h)
                    ))));
                }
            }
            if !crops.size.is_multiple_of(multiple) {
                return Err(Error::Setting(
                    Message::setting("crop_size")
                        .then(format!(" {} must be a multiple of {multiple}, the sizes this model makes", crops.size)),
                ));
            }
            (crops.size, crops.size)
        } else {
            // Whole frames make images of one size: every frame must have the first one's.
            let size = |k: u64| (source.scene(k).width, source.scene(k).height);
            let first = size(0);
            if let Some(k) = (0..count).find(|&k| size(k) != first) {
                let (scene, first_scene) = (source.scene(k), source.scene(0));
                return Err(Error::Setting(
                    Message::setting("scenes")
                        .then(format!(
                            ": scene {} is {}×{}, scene {} {}×{}; frames of several sizes need ",
                            scene.name.unwrap_or("?"),
                            scene.width,
                            scene.height,
                            first_scene.name.unwrap_or("?"),
                            first.0,
                            first.1
                        ))
                        .and("crops"),
                ));
            }
            let w = centered_window(first.0, first.1, multiple)?;
            (w.width, w.height)
        };
        sampling.width = width as usize;
        sampling.height = height as usize;
        let user_prompts = prompts.len();
        let prompts = prompts.into_iter().chain(scene_prompts).collect();
        Ok(DatasetSettings {
            seed,
            count,
            source,
            crops,
            control_depth,
            controls: LabelControls::default(),
            regions: RegionSettings::default(),
            models,
            prompts,
            user_prompts,
            templates,
            wildcards: loaded,
            negative_prompt,
            sampling,
            ip_sets,
        })
    }

    /// These settings with `kinds` of control made beside the depth control, edges where the depth
    /// jumps by `depth_jump`.
    /// The controls the ControlNets see are made too.
    pub fn with_controls(mut self, kinds: &[ControlKind], depth_jump: f32) -> Result<DatasetSettings> {
        let mut kinds = kinds.to_vec();
        kinds.extend(self.models.iter().flat_map(ModelSettings::control_kinds));
        self.controls = LabelControls::new(&kinds, depth_jump, &self.source.categories())?;
        Ok(self)
    }

    /// These settings with a prompt and a strength per category, from the scenes'
    /// categories.json and `flags`: the schedule then runs at the largest strength, from the
    /// renders.
    pub fn with_regions(mut self, flags: &RegionFlags) -> Result<DatasetSettings> {
        let given = !flags.prompts.is_empty() || !flags.strengths.is_empty() || flags.background.is_some();
        let Some(models) = &self.models else {
            if given {
                let flag = if flags.prompts.is_empty() { "category_strength" } else { "category_prompt" };
                return Err(Error::Setting(
                    Message::setting(flag).then(" needs a model: a ").and("render_only").then(" set has no prompts"),
                ));
            }
            return Ok(self);
        };
        let scale = Sdxl::probe_vae_scale(&models.model, models.swaps())?;
        let categories = self.source.categories();
        let guides = self.source.category_guides();
        let regions = RegionSettings::new(&categories, &guides, flags, self.sampling.strength, scale)?;
        if regions.has_strengths() {
            self.sampling.strength = Some(regions.largest());
            self.sampling.first_step()?;
        }
        self.regions = regions;
        Ok(self)
    }

    /// Whether the images are the shaded renders, with no diffusion (`--render-only`).
    pub fn render_only(&self) -> bool {
        self.models.is_none()
    }

    /// Whether each image needs its crop's shaded render: as img2img's start, or as the image.
    pub fn wants_shaded(&self) -> bool {
        self.render_only() || self.sampling.strength.is_some()
    }

    /// Images per scene.
    pub fn images_per_scene(&self) -> u64 {
        self.crops.count.max(1) as u64
    }

    /// Images in the whole dataset.
    pub fn images(&self) -> u64 {
        self.count * self.images_per_scene()
    }

    /// The frame windows of scene `scene` (seed `scene_seed`)'s images, in crop order.
    pub fn windows(&self, scene: u64, scene_seed: u64) -> Result<Vec<CropWindow>> {
        let info = self.source.scene(scene);
        let (width, height) = (info.width, info.height);
        if self.crops.count == 0 {
            // The image made from a whole frame: the frame cut to the image size, centred.
            return Ok(vec![centered(width, height, self.sampling.width as u32, self.sampling.height as u32)]);
        }
        Ok(vkdiff_render::crops::crop_windows(scene_seed, self.crops.count, self.crops.size, width, height)?)
    }

    /// The prompt (an index into `prompts`) of image `index` of scene `scene`, whose seed is
    /// `seed`: the scene's own, else one of the `--prompt`s drawn from the seed.
    pub fn prompt_of(&self, scene: u64, seed: u64) -> usize {
        match self.source.scene(scene).prompt {
            Some(own) => self.prompts.iter().position(|p| p == own).expect("every scene's prompt is listed"),
            None => crate::choose(seed, crate::Choice::Prompt, self.user_prompts),
        }
    }

    /// Whether any prompt is a template, whose images' prompts are known only as they come.
    pub fn uses_templates(&self) -> bool {
        self.templates.iter().any(PromptTemplate::is_template)
    }

    /// The prompt of an image with `seed` of scene `scene`, whose instances have the categories
    /// `instances`: which of `prompts` ([`DatasetSettings::prompt_of`]), and its expansion from
    /// the seed, the category slots filled from the instances.
    pub fn image_prompt(
        &self,
        scene: u64,
        seed: u64,
        instances: impl IntoIterator<Item = u32>,
    ) -> Result<(usize, Expansion)> {
        let index = self.prompt_of(scene, seed);
        let template = &self.templates[index];
        let slots = template.is_template().then(|| CategorySlots::new(instances, &self.source.categories()));
        Ok((index, template.expand(seed, &self.wildcards, slots.as_ref())?))
    }
}

/// A render-only set's images are cut as SDXL's are: sides multiples of its VAE's 8.
const RENDER_ONLY_MULTIPLE: u32 = 8;

/// The prompts, styles and sampling of a diffusion set, before any model loads.
fn check_diffusion(
    models: &ModelSettings,
    prompts: &[PromptTemplate],
    wildcards: &Wildcards,
    every_scene_has_one: bool,
    negative_prompt: &Option<String>,
    sampling: &Sampling,
    ip_sets: &[Vec<PathBuf>],
) -> Result<()> {
    if (prompts.is_empty() && !every_scene_has_one) || prompts.iter().any(|p| p.text().trim().is_empty()) {
        return Err(Error::Setting(
            Message::setting("prompt").then(" (or ").and("prompts").then(
                " FILE) must give at least one prompt, none of them empty, unless every scene has its prompt.txt",
            ),
        ));
    }
    match (&models.ip_adapter, ip_sets.is_empty()) {
        (Some(_), true) => {
            return Err(Error::Setting(
                Message::setting("ip_adapter")
                    .then(" needs style images: ")
                    .and("ip_image")
                    .then(" (one set) or ")
                    .and("ip_set")
                    .then(" A,B (repeatable)"),
            ))
        }
        (None, false) => {
            return Err(Error::Setting(
                Message::setting("ip_image").then("/").and("ip_set").then(" need ").and("ip_adapter"),
            ))
        }
        _ => {}
    }
    if ip_sets.iter().any(|set| set.is_empty()) {
        return Err(Error::Setting(Message::setting("ip_set").then(": a set names no image")));
    }
    models.check()?;
    sampling.check(&SchedulerConfig::of_model(&models.model)?)?;
    // A template's expansions are checked as they come; its literal pieces now.
    let pieces = prompts.iter().flat_map(|t| wildcards.literals(t));
    for prompt in pieces.chain(negative_prompt.as_deref()) {
        sampling.prompt_syntax.check(prompt)?;
    }
    Ok(())
}

/// A render-only set takes the scene flags only: a prompt, a style or a strength would be
/// silently unused.
fn check_render_only(
    prompts: &[String],
    negative_prompt: &Option<String>,
    sampling: &Sampling,
    ip_sets: &[Vec<PathBuf>],
    wildcards: &Option<PathBuf>,
) -> Result<()> {
    let unused = if !prompts.is_empty() {
        Some(Message::setting("prompt").then("/").and("prompts"))
    } else if negative_prompt.is_some() {
        Some(Message::setting("negative_prompt"))
    } else if !ip_sets.is_empty() {
        Some(Message::setting("ip_image").then("/").and("ip_set"))
    } else if sampling.strength.is_some() {
        Some(Message::setting("strength"))
    } else if wildcards.is_some() {
        Some(Message::setting("wildcards"))
    } else {
        None
    };
    match unused {
        Some(flag) => Err(Error::Setting(
            Message::setting("render_only")
                .then(" makes the shaded renders the images, with no model: drop ")
                .append(flag),
        )),
        None => Ok(()),
    }
}

/// The prompts of a `prompts` file: one a line, trimmed, blank lines skipped.
pub fn read_prompts(path: &Path) -> Result<Vec<String>> {
    let text = std::fs::read_to_string(path).map_err(|e| {
        Error::Context(
            Message::setting("prompts").then(format!(" {}", path.display())),
            Box::new(Error::Config(e.to_string())),
        )
    })?;
    Ok(text.lines().map(str::trim).filter(|l| !l.is_empty()).map(String::from).collect())
}

/// `prompts` once each, in order of first appearance.
fn distinct<'a>(prompts: impl Iterator<Item = &'a str>) -> Vec<String> {
    let mut seen = std::collections::HashSet::new();
    prompts.filter(|p| seen.insert(*p)).map(String::from).collect()
}
