//! The dataset folder: `dataset.json` (settings and version, written once by whichever process
//! comes first and checked by every later one), one folder per kind of file, and one record per
//! finished image. An image is done when its record exists, carries the dataset's fingerprint,
//! and every file it lists has the size it lists; anything less is made again.

use super::plan::{index_of, ImageFiles, Shard, FOLDERS};
use super::settings::DatasetSettings;
use super::settings_record::first_difference;
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use vkdiff_formats::Error as FileError;
use vkdiff_pipeline::files::{partial_path, write_atomic, PARTIAL};
use vkdiff_render::coco::{mushroom_category, serialize_sorted, Annotation, Category};
use vkdiff_setting::{version, Message};

pub const MANIFEST: &str = "dataset.json";
pub const ANNOTATIONS: &str = "annotations.json";
const FORMAT: &str = "vkdiff-dataset/1";
/// dataset.json's list of the versions that `--allow-version-change` let finish the set.
const ALLOWED: &str = "versions_allowed";

/// Whether a build of another version than the one that made a set may add to it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum VersionChange {
    /// Refused: another build's kernels may give other bytes.
    #[default]
    Refuse,
    /// Allowed, and recorded in dataset.json (`--allow-version-change`).
    Allow,
}

/// What one finished image left: its files' sizes, its COCO image entry and its annotations
/// (ids local to the image: the instance's id in its mask).
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
pub struct ImageRecord {
    pub fingerprint: String,
    pub files: BTreeMap<String, u64>,
    pub image: Value,
    #[serde(serialize_with = "serialize_sorted")]
    pub annotations: Vec<Annotation>,
}

/// An opened dataset folder whose settings are this run's.
#[derive(Clone)]
pub struct Dataset {
    pub dir: PathBuf,
    pub fingerprint: String,
    pub images: u64,
    pub scenes: u64,
    pub images_per_scene: u64,
    /// dataset.json's `settings`.
    pub settings: Value,
}

/// FNV-1a, 64 bits: a stable digest of the settings (not a security measure).
pub(crate) fn fnv1a(text: &str) -> String {
    let hash = text.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ b as u64).wrapping_mul(0x0100_0000_01b3));
    format!("{hash:016x}")
}

/// What the images of a shard still need.
#[derive(Default)]
pub struct Pending {
    /// Scenes with images to make, each with those images' indices.
    pub scenes: Vec<(u64, Vec<u64>)>,
    /// Images of the shard already done, and the bytes their files and records hold.
    pub done: u64,
    pub done_bytes: u64,
    /// Records found but not whole, each with why; their images are made again.
    pub redo: Vec<String>,
}

impl Pending {
    pub fn images(&self) -> u64 {
        self.scenes.iter().map(|(_, images)| images.len() as u64).sum()
    }
}

impl Dataset {
    /// Creates the folder for `settings`, or opens it when it was made with the same settings
    /// by this version (or `versions` allows another); refuses one made otherwise (naming the
    /// first differing flag, or both versions) or a folder that is not a dataset. Nothing is
    /// written before these checks pass.
    pub fn open(dir: &Path, settings: &DatasetSettings, versions: VersionChange) -> Result<Dataset> {
        let wanted = manifest(settings);
        let path = dir.join(MANIFEST);
        let io = |p: &Path| {
            let p = p.to_path_buf();
            move |e| FileError::Io { path: p, source: e }
        };
        if !path.is_file() {
            refuse_foreign_folder(dir)?;
            std::fs::create_dir_all(dir).map_err(io(dir))?;
            create_once(&path, &to_text(&wanted))?;
        }
        let mut recorded = read_manifest(&path)?;
        if recorded["format"] != wanted["format"] {
            return Err(Error::Setting(
                Message::text(format!(
                    "{} is a {} folder; this vkdiff writes {FORMAT}: give another ",
                    dir.display(),
                    recorded["format"]
                ))
                .and("out"),
            ));
        }
        if let Some(diff) = first_difference(&recorded["settings"], &wanted["settings"]) {
            return Err(Error::Setting(
                Message::text(format!("{} holds a dataset made with other settings: ", dir.display()))
                    .append(diff)
                    .then("; use the same settings to finish it, or another ")
                    .and("out"),
            ));
        }
        accept_version(dir, &mut recorded, versions)?;
        for folder in FOLDERS {
            std::fs::create_dir_all(dir.join(folder)).map_err(io(&dir.join(folder)))?;
        }
        // The set keeps the fingerprint it was made with: records of an allowed version change
        // stay done.
        Ok(Dataset::from_manifest(dir, recorded))
    }

    /// A finished or unfinished dataset that this version may merge (see [`Dataset::open`]).
    pub fn for_merge(dir: &Path, versions: VersionChange) -> Result<Dataset> {
        let mut manifest = read_manifest(&manifest_path(dir)?)?;
        accept_version(dir, &mut manifest, versions)?;
        Ok(Dataset::from_manifest(dir, manifest))
    }

    /// A finished or unfinished dataset, as `dataset.json` describes it (for reading).
    pub fn read(dir: &Path) -> Result<Dataset> {
        Ok(Dataset::from_manifest(dir, read_manifest(&manifest_path(dir)?)?))
    }

    fn from_manifest(dir: &Path, m: Value) -> Dataset {
        let number = |k: &str| m[k].as_u64().unwrap_or(0);
        Dataset {
            dir: dir.to_path_buf(),
            fingerprint: m["fingerprint"].as_str().unwrap_or_default().to_string(),
            images: number("images"),
            scenes: number("scenes"),
            images_per_scene: number("images") / number("scenes").max(1),
            settings: m["settings"].clone(),
        }
    }

    /// The set's COCO categories: the ones its scenes named (dataset.json), else the
    /// procedural bed's one.
    pub fn categories(&self) -> Vec<Category> {
        serde_json::from_value(self.settings["categories"].clone()).unwrap_or_else(|_| vec![mushroom_category()])
    }

    pub fn files(&self, index: u64) -> ImageFiles {
        ImageFiles::new(index, self.images)
    }

    /// Images whose record is there (whether whole is for [`crate::merge`] to check).
    pub fn recorded(&self) -> u64 {
        (0..self.images).filter(|&i| self.dir.join(self.files(i).record).is_file()).count() as u64
    }

    /// Image `index`'s record if the image is whole; else why not (`None` when there is no record).
    pub fn finished(&self, index: u64) -> std::result::Result<ImageRecord, Option<String>> {
        let files = self.files(index);
        let text = match std::fs::read(self.dir.join(&files.record)) {
            Ok(text) => text,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Err(None),
            Err(e) => return Err(Some(format!("{}: {e}", files.record))),
        };
        let record: ImageRecord =
            serde_json::from_slice(&text).map_err(|e| Some(format!("{}: unreadable ({e})", files.record)))?;
        if record.fingerprint != self.fingerprint {
            return Err(Some(format!(
                "{} was made with other settings (fingerprint {}, the dataset's {})",
                files.record, record.fingerprint, self.fingerprint
            )));
        }
        for name in files.outputs().into_iter().chain(record.files.keys().map(String::as_str)) {
            let want = record.files.get(name).copied();
            let got = std::fs::metadata(self.dir.join(name)).ok().map(|m| m.len());
            if want.is_none() || got != want {
                return Err(Some(format!(
                    "{name} is {} bytes, its record says {}",
                    got.map_or("missing, 0".into(), |g| g.to_string()),
                    want.map_or("nothing".into(), |w| w.to_string())
                )));
            }
        }
        Ok(record)
    }

    /// The images of `shard` still to make, after removing the temporary files its earlier runs
    /// left (another shard's are never touched: they may be in the middle of a write).
    pub fn pending(&self, shard: Shard) -> Result<Pending> {
        self.remove_partials(&|index| shard.owns_scene(index / self.images_per_scene.max(1)))?;
        let mut pending = Pending::default();
        for scene in (0..self.scenes).filter(|&s| shard.owns_scene(s)) {
            let mut todo = Vec::new();
            for index in scene * self.images_per_scene..(scene + 1) * self.images_per_scene {
                match self.finished(index) {
                    Ok(record) => {
                        let record_file = std::fs::metadata(self.dir.join(self.files(index).record));
                        pending.done += 1;
                        pending.done_bytes += record.files.values().sum::<u64>() + record_file.map_or(0, |m| m.len());
                    }
                    Err(why) => {
                        pending.redo.extend(why);
                        todo.push(index);
                    }
                }
            }
            if !todo.is_empty() {
                pending.scenes.push((scene, todo));
            }
        }
        Ok(pending)
    }

    /// Removes `.NAME.partial-PID` files of the images `owned` accepts.
    pub(crate) fn remove_partials(&self, owned: &dyn Fn(u64) -> bool) -> Result<()> {
        for folder in FOLDERS {
            let dir = self.dir.join(folder);
            let entries = std::fs::read_dir(&dir).map_err(|e| FileError::Io { path: dir.clone(), source: e })?;
            for entry in entries.flatten() {
                let name = entry.file_name().to_string_lossy().into_owned();
                if name.starts_with('.') && name.contains(PARTIAL) && index_of(&name).is_some_and(owned) {
                    let _ = std::fs::remove_file(entry.path());
                }
            }
        }
        Ok(())
    }

    /// Writes an image's files, then its record: the image counts as done only once all are
    /// whole. Returns the bytes written.
    pub fn write_image(
        &self,
        index: u64,
        outputs: &[(&str, &[u8])],
        image: Value,
        annotations: Vec<Annotation>,
    ) -> Result<u64> {
        let mut files = BTreeMap::new();
        for (name, bytes) in outputs {
            write_atomic(&self.dir.join(name), bytes)?;
            files.insert(name.to_string(), bytes.len() as u64);
        }
        let written = files.values().sum::<u64>();
        let record = ImageRecord { fingerprint: self.fingerprint.clone(), files, image, annotations };
        let mut text = serde_json::to_string(&record).expect("records serialise");
        text.push('\n');
        write_atomic(&self.dir.join(self.files(index).record), text.as_bytes())?;
        Ok(written + text.len() as u64)
    }
}

/// dataset.json for `settings`.
fn manifest(settings: &DatasetSettings) -> Value {
    let s = settings.to_json();
    let mut manifest = json!({
        "format": FORMAT,
        "vkdiff": version(),
        "fingerprint": fnv1a(&format!("{FORMAT} {} {s}", version())),
        "scenes": settings.count,
        "images": settings.images(),
        "layout": {
            "images": "images/NNNNNN.png: the generated images, with their settings as vkdiff gen writes them",
            "depth": "depth/NNNNNN.exr: planar depth in metres (channel Z), the ControlNet's input",
            "control": "control/NNNNNN.png: the depth as the ControlNet saw it",
            "masks": "masks/NNNNNN.png: 16-bit instance ids, 0 = compost, k = the annotation with mask_id k",
            "init": "init/NNNNNN.png: with --init-strength, the shaded render each image started from (img2img)",
            "records": "records/NNNNNN.json: one finished image's COCO entry and annotations",
            "annotations": "annotations.json: COCO instance segmentation of every image, once all are done",
        },
        "settings": s,
    });
    if settings.regions.has_strengths() {
        manifest["layout"]["strength"] = json!(
            "init/NNNNNN.strength.png: each pixel's img2img strength (0-255 for 0-1), feathered as the denoiser saw it"
        );
    }
    if !settings.controls.kinds.is_empty() {
        manifest["layout"]["controls"] =
            json!("control/NNNNNN.<kind>.png: --controls and the controls the ControlNets see, each computed from the image's labels (docs/controls.md)");
    }
    manifest
}

fn manifest_path(dir: &Path) -> Result<PathBuf> {
    let path = dir.join(MANIFEST);
    if !path.is_file() {
        return Err(Error::Config(format!("{}: no {MANIFEST}; not a vkdiff dataset folder", dir.display())));
    }
    Ok(path)
}

/// Accepts this version for the set `manifest` describes: the one that made it, one allowed
/// before, or (with [`VersionChange::Allow`]) a new one, which dataset.json then lists.
fn accept_version(dir: &Path, manifest: &mut Value, versions: VersionChange) -> Result<()> {
    let made_by = manifest["vkdiff"].as_str().unwrap_or("unknown").to_string();
    let allowed = manifest[ALLOWED].as_array().is_some_and(|a| a.iter().any(|v| v == version()));
    if made_by == version() || allowed {
        return Ok(());
    }
    if versions == VersionChange::Refuse {
        return Err(Error::Setting(
            Message::text(format!(
                "{} was made by vkdiff {made_by}; this is vkdiff {}, whose kernels may give other bytes: finish it \
                with vkdiff {made_by}, give another ",
                dir.display(),
                version()
            ))
            .and("out")
            .then(", or pass ")
            .and("allow_version_change"),
        ));
    }
    let list = manifest.as_object_mut().expect("a checked manifest is an object").entry(ALLOWED).or_insert(json!([]));
    if let Some(list) = list.as_array_mut() {
        list.push(json!(version()));
    }
    write_atomic(&dir.join(MANIFEST), to_text(manifest).as_bytes())?;
    Ok(())
}

fn to_text(v: &Value) -> String {
    let mut text = serde_json::to_string_pretty(v).expect("JSON values serialise");
    text.push('\n');
    text
}

fn read_manifest(path: &Path) -> Result<Value> {
    let text = std::fs::read_to_string(path).map_err(|e| FileError::Io { path: path.to_path_buf(), source: e })?;
    let value: Value = serde_json::from_str(&text)
        .map_err(|e| FileError::Format { path: path.to_path_buf(), why: format!("not JSON ({e})") })?;
    if !value["format"].is_string()
        || !value["settings"].is_object()
        || !value["images"].is_u64()
        || !value["scenes"].is_u64()
        || !value["fingerprint"].is_string()
    {
        return Err(FileError::Format { path: path.to_path_buf(), why: "not a vkdiff dataset manifest".into() }.into());
    }
    Ok(value)
}

/// Writes `text` to `path` unless some process did first (shards starting together): the file
/// is linked into place whole, and the loser's copy is dropped.
fn create_once(path: &Path, text: &str) -> Result<()> {
    let tmp = partial_path(path);
    let io = |e| Error::from(FileError::Io { path: path.to_path_buf(), source: e });
    std::fs::write(&tmp, text).map_err(io)?;
    let linked = std::fs::File::open(&tmp).and_then(|f| f.sync_all()).and_then(|_| std::fs::hard_link(&tmp, path));
    let _ = std::fs::remove_file(&tmp);
    match linked {
        Err(e) if e.kind() != std::io::ErrorKind::AlreadyExists => Err(io(e)),
        _ => Ok(()),
    }
}

/// A folder that exists, holds anything but a dataset's own files, and has no dataset.json is
/// someone else's: never write into it.
fn refuse_foreign_folder(dir: &Path) -> Result<()> {
    let Ok(entries) = std::fs::read_dir(dir) else { return Ok(()) };
    let ours = |name: &str| {
        FOLDERS.contains(&name) || name == ANNOTATIONS || (name.starts_with('.') && name.contains(PARTIAL))
    };
    let foreign: Vec<String> =
        entries.flatten().map(|e| e.file_name().to_string_lossy().into_owned()).filter(|n| !ours(n)).collect();
    if let Some(first) = foreign.first() {
        return Err(Error::Setting(Message::setting("out").then(format!(
            " {}: the folder holds other files ({first}, …) and no {MANIFEST}; give a new or empty folder",
            dir.display()
        ))));
    }
    Ok(())
}
