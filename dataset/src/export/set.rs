//! A finished dataset folder as the exports read it: its merged COCO file, each image with its
//! annotations and its split, every file checked to be there before anything is written.

use super::splits::{Split, SplitFractions};
use crate::error::{Error, Result};
use crate::folder::{Dataset, ANNOTATIONS};
use serde_json::{json, Value};
use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use vkdiff_formats::Error as FileError;

pub struct SetImage {
    /// The COCO image entry, as annotations.json holds it.
    pub entry: Value,
    pub annotations: Vec<Value>,
    pub scene_seed: u64,
    pub split: Split,
}

impl SetImage {
    pub fn file_name(&self) -> &str {
        self.entry["file_name"].as_str().expect("checked when read")
    }

    /// Every file of the set this image's entry names (`file_name`, `depth_file`, …), by key.
    pub fn files(&self) -> Vec<(&str, &str)> {
        let object = self.entry.as_object().expect("checked when read");
        object
            .iter()
            .filter(|(k, _)| *k == "file_name" || k.ends_with("_file"))
            .filter_map(|(k, v)| Some((k.as_str(), v.as_str()?)))
            .collect()
    }
}

pub struct FinishedSet {
    pub dir: PathBuf,
    /// annotations.json's `info`, `licenses` and `categories`.
    pub info: Value,
    pub licenses: Value,
    pub categories: Value,
    pub images: Vec<SetImage>,
    pub fractions: SplitFractions,
}

impl FinishedSet {
    /// Reads the set in `dir`, refusing a folder that is not a dataset, one not merged yet, and
    /// one whose files are not all there.
    pub fn read(dir: &Path, fractions: &SplitFractions) -> Result<FinishedSet> {
        let dataset = Dataset::read(dir)?;
        let path = dir.join(ANNOTATIONS);
        if !path.is_file() {
            return Err(Error::Config(format!(
                "{}: no {ANNOTATIONS} yet, so the set is not finished ({} of {} images made); once every shard is \
                 done, vkdiff dataset merge {}",
                dir.display(),
                dataset.recorded(),
                dataset.images,
                dir.display()
            )));
        }
        let bad = |why: String| Error::from(FileError::Format { path: path.clone(), why });
        let text = std::fs::read(&path).map_err(|e| FileError::Io { path: path.clone(), source: e })?;
        let mut coco: Value = serde_json::from_slice(&text).map_err(|e| bad(format!("not JSON ({e})")))?;
        let (Value::Array(images), Value::Array(annotations)) = (coco["images"].take(), coco["annotations"].take())
        else {
            return Err(bad("not a COCO file: no images or annotations list".into()));
        };
        let mut by_image: HashMap<u64, Vec<Value>> = HashMap::new();
        for a in annotations {
            let id = a["image_id"].as_u64().ok_or_else(|| bad(format!("annotation {} has no image_id", a["id"])))?;
            by_image.entry(id).or_default().push(a);
        }
        let mut read = Vec::with_capacity(images.len());
        for entry in images {
            let (Some(id), Some(scene_seed), Some(_), Some(1..), Some(1..)) = (
                entry["id"].as_u64(),
                entry["scene_seed"].as_u64(),
                entry["file_name"].as_str(),
                entry["width"].as_u64(),
                entry["height"].as_u64(),
            ) else {
                return Err(bad(format!("image {} lacks an id, file_name, width, height or scene_seed", entry["id"])));
            };
            let image = SetImage {
                annotations: by_image.remove(&id).unwrap_or_default(),
                split: Split::Train,
                scene_seed,
                entry,
            };
            for (_, file) in image.files() {
                if !dir.join(file).is_file() {
                    return Err(bad(format!("image {id}'s {file} is missing from the folder")));
                }
            }
            read.push(image);
        }
        let scenes: Vec<u64> = read.iter().map(|i| i.scene_seed).collect::<BTreeSet<u64>>().into_iter().collect();
        let split_of: HashMap<u64, Split> = scenes.iter().copied().zip(fractions.of_scenes(&scenes)).collect();
        for image in &mut read {
            image.split = split_of[&image.scene_seed];
        }
        if let Some(id) = by_image.keys().min() {
            return Err(bad(format!("annotations of image {id}, which the file does not list")));
        }
        Ok(FinishedSet {
            dir: dir.to_path_buf(),
            info: coco["info"].take(),
            licenses: coco.get_mut("licenses").map_or(json!([]), Value::take),
            categories: coco["categories"].take(),
            images: read,
            fractions: *fractions,
        })
    }

    /// The splits an export writes: train, and val and test where their fraction is above 0
    /// (even when no scene fell there: the files trainers expect are there, empty).
    pub fn splits(&self) -> Vec<Split> {
        let f = &self.fractions;
        Split::ALL
            .into_iter()
            .filter(|s| *s == Split::Train || (*s == Split::Val && f.val > 0.0) || (*s == Split::Test && f.test > 0.0))
            .collect()
    }

    pub fn scenes_per_split(&self) -> BTreeMap<Split, u64> {
        let mut scenes: BTreeMap<Split, BTreeSet<u64>> = BTreeMap::new();
        for image in &self.images {
            scenes.entry(image.split).or_default().insert(image.scene_seed);
        }
        scenes.into_iter().map(|(split, seeds)| (split, seeds.len() as u64)).collect()
    }

    /// The set's `info`, with the split this export wrote and how.
    pub fn info_of(&self, split: Split) -> Value {
        let mut info = self.info.clone();
        info["split"] = json!({
            "name": split.name(),
            "val_fraction": self.fractions.val,
            "test_fraction": self.fractions.test,
            "seed": self.fractions.seed,
            "by": "scene_seed",
        });
        info
    }

    pub fn in_split(&self, split: Split) -> impl Iterator<Item = &SetImage> {
        self.images.iter().filter(move |i| i.split == split)
    }
}
