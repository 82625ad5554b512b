//! `vkdiff dataset export`: a finished dataset folder in the layout a trainer reads (COCO with
//! splits, Ultralytics YOLO segmentation or pose, WebDataset shards, a Hugging Face image folder,
//! BOP scenes), split by scene. The dataset folder is only read; the export is built in a hidden
//! sibling of OUT and renamed into place whole, so a killed export leaves no folder that looks
//! finished.

mod bop;
mod bop_image;
mod bop_json;
mod coco;
mod excluded;
mod hf;
mod hf_card;
mod polygons;
mod set;
mod splits;
mod staging;
mod webdataset;
mod yolo;
mod yolo_pose;

pub use bop::BopWritten;
pub use excluded::{Exclusion, EXCLUDED};
pub use splits::{Split, SplitFractions};

use crate::error::{Error, Result};
pub(crate) use set::{FinishedSet, SetImage};
use staging::Staging;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use vkdiff_setting::Message;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExportFormat {
    /// `train.json`, `val.json`, `test.json` beside the set's files.
    Coco,
    /// Ultralytics' segmentation layout with `data.yaml`.
    Yolo,
    /// Ultralytics' pose layout: boxes and keypoints, `kpt_shape` in `data.yaml`.
    YoloPose,
    /// Tar shards of samples (`KEY.png`, `KEY.json`, `KEY.mask.png`, `KEY.depth.exr`).
    WebDataset,
    /// A folder `datasets.load_dataset("imagefolder", data_dir=OUT)` loads.
    Hf,
    /// BOP scenes (`{split}/{scene}/`) with the images in `rgb/`, poses, depth and masks.
    Bop,
}

pub struct ExportOptions {
    pub format: ExportFormat,
    pub splits: SplitFractions,
    /// Copy the files; else hard-link them where the file system allows (and copy elsewhere).
    pub copy: bool,
    /// Replace an existing OUT.
    pub force: bool,
    /// WebDataset: a shard is closed once it holds this many bytes.
    pub shard_bytes: u64,
    /// Images the audit flagged, left out of every format.
    pub exclude: Exclusion,
}

/// What an export wrote.
#[derive(Debug, Default)]
pub struct Exported {
    /// Images and scenes per split.
    pub images: BTreeMap<Split, u64>,
    pub scenes: BTreeMap<Split, u64>,
    pub annotations: u64,
    /// Files copied: all with `--copy`, else those a hard link could not reach.
    pub copied: u64,
    pub linked: u64,
    /// YOLO: how well the polygons cover their masks.
    pub polygons: Option<PolygonFit>,
    /// WebDataset: tar files written.
    pub shards: usize,
    /// YOLO pose: keypoints per label line.
    pub keypoints: Option<usize>,
    pub bop: Option<BopWritten>,
    /// Images left out by the audit (`--exclude-flagged`, `--min-boundary-score`).
    pub dropped: Option<u64>,
}

/// IoU of each instance's polygon with its mask, over every instance exported.
#[derive(Debug, Clone, Copy)]
pub struct PolygonFit {
    pub instances: u64,
    pub min_iou: f64,
    pub mean_iou: f64,
    pub points: u64,
}

/// Exports the finished set in `dir` to `out`; `progress(done, total)` after each image.
pub fn export(
    dir: &Path,
    out: &Path,
    options: &ExportOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Exported> {
    options.splits.check()?;
    if options.format == ExportFormat::WebDataset && options.shard_bytes == 0 {
        return Err(Error::Setting(Message::setting("shard_size").then(" must be at least 1 MB")));
    }
    options.exclude.check()?;
    check_out(dir, out, options.force)?;
    let mut set = FinishedSet::read(dir, &options.splits)?;
    let excluded = (!options.exclude.is_empty()).then(|| excluded::exclude(&mut set, &options.exclude)).transpose()?;
    if set.images.is_empty() {
        return Err(Error::Config(format!("every image of {} is excluded: nothing to export", dir.display())));
    }
    // What the set's labels refuse is refused before anything is written.
    let models = (options.format == ExportFormat::Bop).then(|| bop::checked_models(&set)).transpose()?;
    let most_keypoints =
        (options.format == ExportFormat::YoloPose).then(|| yolo_pose::keypoints_per_line(&set)).transpose()?;
    let mut staging = Staging::beside(out, options.copy)?;
    let mut exported = Exported::default();
    for split in set.splits() {
        exported.images.insert(split, 0);
        exported.scenes.insert(split, 0);
    }
    for image in &set.images {
        *exported.images.entry(image.split).or_default() += 1;
        exported.annotations += image.annotations.len() as u64;
    }
    for (split, scenes) in set.scenes_per_split() {
        exported.scenes.insert(split, scenes);
    }
    if let Some(list) = &excluded {
        exported.dropped = list["dropped"].as_array().map(|d| d.len() as u64);
        let text = serde_json::to_string_pretty(list).expect("JSON values serialise");
        if let Err(e) = staging.write(EXCLUDED, text.as_bytes()) {
            staging.abandon();
            return Err(e);
        }
    }
    let written = match options.format {
        ExportFormat::Coco => coco::write(&set, &mut staging, progress),
        ExportFormat::Yolo => yolo::write(&set, &mut staging, progress).map(|fit| exported.polygons = Some(fit)),
        ExportFormat::YoloPose => {
            let most = most_keypoints.unwrap_or_default();
            yolo_pose::write(&set, most, &mut staging, progress).map(|_| exported.keypoints = Some(most))
        }
        ExportFormat::WebDataset => {
            webdataset::write(&set, &mut staging, options.shard_bytes, progress).map(|n| exported.shards = n)
        }
        ExportFormat::Hf => hf::write(&set, &mut staging, progress),
        ExportFormat::Bop => {
            bop::write(&set, &models.unwrap_or_default(), &mut staging, progress).map(|b| exported.bop = Some(b))
        }
    };
    if let Err(e) = written {
        staging.abandon();
        return Err(e);
    }
    (exported.copied, exported.linked) = (staging.copied, staging.linked);
    staging.publish(out, options.force)?;
    Ok(exported)
}

/// OUT must be new (or `force`d) and lie apart from the dataset folder, which is never touched.
fn check_out(dir: &Path, out: &Path, force: bool) -> Result<()> {
    let absolute = |p: &Path| -> PathBuf {
        // OUT may not exist yet: resolve the part of it that does.
        let mut missing = Vec::new();
        let mut at = p.to_path_buf();
        loop {
            if let Ok(real) = at.canonicalize() {
                return missing.into_iter().rev().fold(real, |path: PathBuf, part| path.join(part));
            }
            match (at.file_name().map(|n| n.to_os_string()), at.parent()) {
                (Some(name), Some(parent)) => {
                    missing.push(name);
                    at = if parent.as_os_str().is_empty() { PathBuf::from(".") } else { parent.to_path_buf() };
                }
                _ => return p.to_path_buf(),
            }
        }
    };
    let (d, o) = (absolute(dir), absolute(out));
    if o.starts_with(&d) || d.starts_with(&o) {
        return Err(Error::Setting(Message::setting("out").then(format!(
            " {} overlaps the dataset folder {}: export to a folder outside it",
            out.display(),
            dir.display()
        ))));
    }
    if out.is_file() {
        return Err(Error::Setting(
            Message::setting("out").then(format!(" {} is a file; give a folder", out.display())),
        ));
    }
    if out.exists() && !force {
        return Err(Error::Setting(
            Message::setting("out")
                .then(format!(" {} exists: give ", out.display()))
                .and("force")
                .then(" to replace it"),
        ));
    }
    Ok(())
}

/// The stem of a set file name, `images/000042.png` → `000042`.
fn stem(file_name: &str) -> &str {
    let name = file_name.rsplit('/').next().unwrap_or(file_name);
    name.split('.').next().unwrap_or(name)
}
