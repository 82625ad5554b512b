//! What the dataset loop hands on: each image with its record (the PNG text and COCO entry
//! `vkdiff gen` would give it), and the writer thread that encodes and writes its files.

use super::disk::DiskGuard;
use super::folder::Dataset;
use super::scenes::SceneImage;
use super::settings::DatasetSettings;
use crate::error::Result;
use serde_json::{json, Value};
use std::path::PathBuf;
use std::sync::mpsc::{sync_channel, SyncSender};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use vkdiff_pipeline::files::png_bytes;
use vkdiff_pipeline::{Expansion, GenSettings, RgbImage, TextToImage, WorkflowModels};
use vkdiff_render::control::ControlKind;

/// One image on its way through the denoiser.
pub(super) struct Item {
    pub(super) scene: SceneImage,
    pub(super) seed: u64,
    /// Which of the settings' prompts (templates) it takes.
    pub(super) template: usize,
    /// Its prompt: the template expanded, with the choices that made it.
    pub(super) prompt: Expansion,
    pub(super) style: Option<usize>,
}

/// An image to write: everything the writer thread needs, nothing it must compute on the GPU.
pub(super) struct Finished {
    index: u64,
    scene: SceneImage,
    image: RgbImage,
    text: std::collections::BTreeMap<String, String>,
    entry: Value,
}

/// The image's PNG text (as `vkdiff gen` would write it for the same settings) and its COCO
/// entry; `round` counts its regenerations.
pub(super) fn finish(
    s: &DatasetSettings,
    models: &WorkflowModels,
    round: u64,
    item: Item,
    image: RgbImage,
) -> Finished {
    let index = item.scene.index;
    let files = super::plan::ImageFiles::new(index, s.images());
    let ip_images: Vec<PathBuf> = item.style.map(|k| s.ip_sets[k].clone()).unwrap_or_default();
    let uses_depth = models.settings.control_kinds().contains(&ControlKind::Depth);
    let gen = GenSettings {
        models: models.settings.clone(),
        job: TextToImage {
            prompt: item.prompt.prompt.clone(),
            negative_prompt: s.negative_prompt.clone(),
            seed: item.seed,
            sampling: s.sampling.clone(),
        },
        depth: uses_depth.then(|| PathBuf::from(&files.depth)),
        control_images: (item.scene.controls.iter())
            .filter(|c| models.settings.control_kinds().contains(&c.kind))
            .map(|c| (c.kind, PathBuf::from(&c.file)))
            .collect(),
        ip_images: ip_images.clone(),
        init_image: item.scene.init.as_ref().map(|_| PathBuf::from(&files.init)),
    };
    let mut entry = item.scene.entry(&files);
    entry["seed"] = json!(item.seed);
    if round > 0 {
        entry["resample"] = json!(round);
    }
    entry["prompt"] = json!(gen.job.prompt);
    entry["negative_prompt"] = json!(s.negative_prompt);
    if s.templates[item.template].is_template() {
        entry["prompt_template"] = json!(s.prompts[item.template]);
        let choices = item.prompt.choices.iter().map(|c| json!({"at": c.at, "choice": c.choice}));
        entry["prompt_choices"] = Value::Array(choices.collect());
    }
    if let (Some(_), Some(strength)) = (&item.scene.init, s.sampling.strength) {
        entry["init_file"] = json!(files.init);
        entry["strength"] = json!(strength);
    }
    if s.regions.has_prompts() {
        let prompts: serde_json::Map<String, Value> =
            s.regions.prompts.iter().map(|(_, name, prompt)| (name.clone(), json!(prompt))).collect();
        entry["region_prompts"] = Value::Object(prompts);
    }
    if item.style.is_some() {
        entry["ip_images"] = json!(ip_images.iter().map(|p| p.display().to_string()).collect::<Vec<_>>());
    }
    let mut text = gen.png_text();
    text.extend(s.regions.png_text());
    if let Some(tiling) = models.sdxl.vae_tiling() {
        text.insert("vae_tile".into(), tiling.tile.to_string());
    }
    Finished { index, text, scene: item.scene, image, entry }
}

/// The writer thread: PNG encoding and every file write happen here, off the denoiser's path.
pub(super) fn start_writer(
    dataset: Dataset,
    disk: DiskGuard,
    batch: usize,
) -> (SyncSender<Finished>, JoinHandle<Result<Duration>>) {
    let (send, receive) = sync_channel::<Finished>(2 * batch);
    let thread = std::thread::spawn(move || {
        let mut busy = Duration::ZERO;
        for f in receive {
            let start = Instant::now();
            let files = dataset.files(f.index);
            let png = png_bytes(&f.image, &f.text)?;
            let annotations = f.scene.dataset_annotations();
            let mut outputs = f.scene.scene_files(&files);
            outputs.extend(f.scene.init.as_ref().map(|(_, png)| (files.init.as_str(), png.as_slice())));
            outputs.push((&files.image, &png));
            disk.written.add(dataset.write_image(f.index, &outputs, f.entry, annotations)?);
            busy += start.elapsed();
        }
        Ok(busy)
    });
    (send, thread)
}
