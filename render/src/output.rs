//! What `vkdiff scene` writes: one folder per scene with depth.exr, instances.png,
//! categories.json, annotations.json, camera.json, control.png, shaded.png and preview.png, plus
//! `crops/<k>/` with the same files (but the preview) for each crop: the scene-folder format
//! `vkdiff dataset --scenes` reads. Files are produced in memory and the folder appears
//! atomically; the bytes depend on the seed and the settings only.

use std::path::Path;

use rayon::prelude::*;
use serde_json::{json, Value};

use crate::coco::{coco_json, instance_masks, mushroom_category, Category};
use crate::control::{control_image, ControlDepth};
use crate::crops::{crop_frame, crop_windows, validate_min_fraction, CropWindow};
use crate::error::{RenderError, Result};
use crate::exr::encode_single_channel;
use crate::frame::Frame;
use crate::png_out::{gray16, rgb8};
use crate::preview::{preview_image, shaded_image};
use crate::scene::{Scene, SceneConfig};
use crate::staging::StagingDir;
use vkdiff_setting::Message;

#[derive(Clone, Debug, PartialEq)]
pub struct OutputOptions {
    pub crops: usize,
    pub crop_size: u32,
    /// Share of an instance's full-frame pixels a crop must hold to keep it.
    pub crop_min_fraction: f64,
    pub control: ControlDepth,
    /// Replace existing scene folders instead of refusing (single scene) or skipping (dataset).
    pub replace: bool,
}

impl Default for OutputOptions {
    fn default() -> Self {
        OutputOptions {
            crops: 0,
            crop_size: 1024,
            crop_min_fraction: 0.1,
            control: ControlDepth::Inverse,
            replace: false,
        }
    }
}

impl OutputOptions {
    fn windows(&self, seed: u64, config: &SceneConfig) -> Result<Vec<CropWindow>> {
        crop_windows(seed, self.crops, self.crop_size, config.width, config.height)
    }
}

/// Checks every setting before anything is rendered or written.
pub fn validate(config: &SceneConfig, options: &OutputOptions) -> Result<()> {
    config.validate()?;
    validate_min_fraction(options.crop_min_fraction)?;
    options.windows(0, config).map(|_| ())
}

/// A named file of a scene folder.
pub type SceneFile = (String, Vec<u8>);

/// Every file of one scene, in a fixed order.
pub fn scene_files(seed: u64, config: &SceneConfig, options: &OutputOptions) -> Result<Vec<SceneFile>> {
    let windows = options.windows(seed, config)?;
    let frame = Scene::build(seed, config)?.render();
    let info = provenance(seed, config);
    let (mut files, preview) =
        rayon::join(|| frame_files(&frame, info.clone(), options.control, ""), || preview_image(&frame));
    files.push(("preview.png".into(), rgb8(config.width, config.height, &preview)));
    let crops: Vec<Vec<SceneFile>> = windows
        .par_iter()
        .enumerate()
        .map(|(k, &window)| {
            let crop = crop_frame(&frame, window, options.crop_min_fraction);
            let mut info = info.clone();
            info["crop"] = json!({
                "index": k,
                "offset_px": [window.x0, window.y0],
                "size_px": window.width,
                "min_fraction": options.crop_min_fraction,
            });
            frame_files(&crop, info, options.control, &format!("crops/{k}/"))
        })
        .collect();
    files.extend(crops.into_iter().flatten());
    Ok(files)
}

/// Where a frame came from, recorded in its annotations.
fn provenance(seed: u64, config: &SceneConfig) -> Value {
    json!({
        "description": "vkdiff procedural white button mushroom bed",
        "version": vkdiff_setting::version(),
        "seed": seed,
        "frame_size_px": [config.width, config.height],
        "density_per_m2": config.bed.density,
        "clumping": config.bed.clumping.clustered_fraction,
    })
}

/// categories.json: the categories, and which each instance (by its id in instances.png) is.
pub fn categories_json(frame: &Frame, categories: &[Category]) -> String {
    let instances: serde_json::Map<String, Value> =
        frame.instances.iter().enumerate().map(|(k, i)| ((k + 1).to_string(), json!(i.category_id))).collect();
    let mut text = serde_json::to_string_pretty(&json!({ "categories": categories, "instances": instances }))
        .expect("categories always serialise");
    text.push('\n');
    text
}

/// The files describing one frame (full or crop) of the procedural bed, under `prefix`.
pub fn frame_files(frame: &Frame, info: Value, control: ControlDepth, prefix: &str) -> Vec<SceneFile> {
    let (w, h) = (frame.width, frame.height);
    let categories = [mushroom_category()];
    let (((depth, ids), shaded), (annotations, control)) = rayon::join(
        || {
            rayon::join(
                || rayon::join(|| encode_single_channel(w, h, "Z", &frame.depth), || gray16(w, h, &frame.ids)),
                || rgb8(w, h, &shaded_image(frame)),
            )
        },
        || {
            rayon::join(
                || coco_json(frame, &instance_masks(frame), &categories, info),
                || rgb8(w, h, &control_image(&frame.depth, control)),
            )
        },
    );
    let camera = frame.camera.as_ref().expect("the procedural bed's frames have their camera");
    let mut camera = serde_json::to_string_pretty(&camera.to_json()).expect("camera JSON always serialises");
    camera.push('\n');
    [
        ("depth.exr", depth),
        ("instances.png", ids),
        ("categories.json", categories_json(frame, &categories).into_bytes()),
        ("annotations.json", annotations.into_bytes()),
        ("camera.json", camera.into_bytes()),
        ("control.png", control),
        // The render-only image: what `dataset --init-strength` starts img2img from.
        ("shaded.png", shaded),
    ]
    .into_iter()
    .map(|(name, bytes)| (format!("{prefix}{name}"), bytes))
    .collect()
}

/// Renders scene `seed` into the folder `dir`, which appears complete or not at all.
pub fn write_scene(dir: &Path, seed: u64, config: &SceneConfig, options: &OutputOptions) -> Result<()> {
    validate(config, options)?;
    // Staging first: an unwritable or occupied folder fails before any rendering.
    let stage = StagingDir::create(dir, options.replace)?;
    for (name, bytes) in scene_files(seed, config, options)? {
        stage.write(&name, &bytes)?;
    }
    stage.commit()
}

/// What a dataset run did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DatasetReport {
    pub written: usize,
    /// Scene folders already complete from an earlier run (kept unless replacing).
    pub skipped: usize,
}

/// Folder of scene `seed` inside a dataset folder.
pub fn scene_folder_name(seed: u64) -> String {
    format!("{seed:06}")
}

/// Scenes `first_seed..first_seed + count` into numbered subfolders of `dir`, in parallel.
pub fn write_dataset(
    dir: &Path,
    first_seed: u64,
    count: u64,
    config: &SceneConfig,
    options: &OutputOptions,
) -> Result<DatasetReport> {
    validate(config, options)?;
    if count == 0 {
        return Err(RenderError::invalid("count", count, "must be at least 1"));
    }
    if first_seed.checked_add(count).is_none() {
        return Err(RenderError::Setting(
            Message::setting("count")
                .then(format!(" {count}: runs past the largest seed from "))
                .and("seed")
                .then(format!(" {first_seed}")),
        ));
    }
    let outcomes: Vec<bool> = (first_seed..first_seed + count)
        .into_par_iter()
        .map(|seed| {
            let target = dir.join(scene_folder_name(seed));
            if target.exists() && !options.replace {
                return Ok(false);
            }
            write_scene(&target, seed, config, options).map(|_| true)
        })
        .collect::<Result<_>>()?;
    let written = outcomes.iter().filter(|&&w| w).count();
    Ok(DatasetReport { written, skipped: outcomes.len() - written })
}
