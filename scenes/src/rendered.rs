//! Scenes rendered elsewhere (`--scenes DIR`), in any format a [`SceneFormat`] reads: the folder is
//! listed and every scene checked from its headers and side files (sizes, categories, prompt) before
//! any work starts; a scene's pixels are read once, when its images are made.

use crate::blenderproc::BlenderProcFrames;
use crate::bop::BopScenes;
use crate::folder::SceneFolders;
use crate::format::{SceneFormat, SceneIndex};
use crate::kubric::KubricSequences;
use crate::labels::CategoryGuide;
use crate::replicator::ReplicatorFrames;
use crate::solo::SoloDataset;
use crate::{Error, Result, SceneError, SceneInfo, SceneSource, SourceFrame};
use rayon::prelude::*;
use serde_json::{json, Map, Value};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use vkdiff_render::coco::Category;
use vkdiff_setting::Message;

/// One listed scene.
#[derive(Clone, Debug)]
struct ListedScene {
    /// The folder's or file's name.
    name: String,
    path: PathBuf,
    width: u32,
    height: u32,
    prompt: Option<String>,
}

/// Scenes rendered elsewhere, every one of them listed and checked.
#[derive(Debug)]
pub struct RenderedScenes {
    dir: PathBuf,
    format: Box<dyn SceneFormat>,
    scenes: Vec<ListedScene>,
    /// Every category the scenes use, by id.
    categories: Vec<Category>,
    /// What the categories.json files say of how categories are generated, by id.
    guides: BTreeMap<u32, CategoryGuide>,
    far: f32,
    /// What opening the folder noticed (a frame left out), for the user.
    notes: Vec<String>,
}

impl RenderedScenes {
    /// Finds the scenes under `dir` (BlenderProc `.hdf5` files, BOP scenes, Replicator BasicWriter
    /// frames, Unity Perception SOLO sequences, Kubric sequences or scene folders; a folder holding more than one of these is refused), in their order, and checks each from its headers and side files: a missing or unreadable file,
    /// sizes that differ, a category listed twice or named two ways is refused in one line naming
    /// the scene. `default_category` names the instances of scene folders without
    /// categories.json; depth at or past `far` is background.
    pub fn open(dir: &Path, default_category: &str, far: f32) -> Result<RenderedScenes> {
        if !(far.is_finite() && far > 0.0) {
            return Err(Error::Setting(Message::setting("far").then(format!(" {far} must be a positive number"))));
        }
        if default_category.trim().is_empty() {
            return Err(Error::Setting(Message::setting("category").then(" must name the category")));
        }
        let refuse = |why: String| Error::Setting(scenes_setting(dir).then(format!(": {why}")));
        let entries = std::fs::read_dir(dir).map_err(|e| within(dir, SceneError::Listing(e)))?;
        let mut paths: Vec<PathBuf> = entries.flatten().map(|e| e.path()).collect();
        paths.sort();
        let hdf5 = BlenderProcFrames::find(&paths);
        let bop = BopScenes::find(dir, &paths);
        let replicator = ReplicatorFrames::find(&paths);
        let solo = SoloDataset::find(dir, &paths);
        let kubric = KubricSequences::find(dir, &paths);
        let folders = SceneFolders::find(&paths).filter(|_| bop.is_none());
        let layouts = [
            (hdf5.is_some(), "BlenderProc .hdf5 files"),
            (bop.is_some(), "BOP scene folders"),
            (replicator.is_some(), "Replicator BasicWriter frames"),
            (solo.is_some(), "Unity Perception SOLO sequences"),
            (kubric.is_some(), "Kubric sequences"),
            (paths.iter().any(|p| crate::folder::is_scene_folder(p)), "vkdiff scene folders"),
        ];
        let held: Vec<&str> = layouts.iter().filter(|(found, _)| *found).map(|(_, what)| *what).collect();
        if held.len() > 1 {
            return Err(refuse(format!("holds {}; one layout per folder", held.join(" and "))));
        }
        let (format, found): (Box<dyn SceneFormat>, Vec<PathBuf>) = if let Some(found) = hdf5 {
            (Box::new(BlenderProcFrames::new(dir).map_err(|e| within(dir, e))?), found)
        } else if let Some(scenes) = bop {
            let (format, images) = BopScenes::open(dir, &scenes).map_err(|e| within(dir, e))?;
            (Box::new(format), images)
        } else if let Some(frames) = replicator {
            let (format, rgb) = ReplicatorFrames::open(dir, &frames).map_err(|e| within(dir, e))?;
            (Box::new(format), rgb)
        } else if let Some(sequences) = solo {
            let (format, steps) = SoloDataset::open(dir, &sequences).map_err(|e| within(dir, e))?;
            (Box::new(format), steps)
        } else if let Some(sequences) = kubric {
            let (format, frames) =
                KubricSequences::open(dir, &sequences, default_category).map_err(|e| within(dir, e))?;
            (Box::new(format), frames)
        } else if let Some(found) = folders {
            (Box::new(SceneFolders::new(default_category)), found)
        } else {
            return Err(refuse(
                "holds no scene folders (each with depth.exr or depth.png and instances.png), no BlenderProc .hdf5 \
                 files, no BOP scenes (folders with scene_camera.json and scene_gt.json, or one such folder) and no \
                 Replicator BasicWriter frames (instance_segmentation_mapping_N.json with its frame's files)\
                 , nor any Unity Perception SOLO sequence (sequence.K/stepM.frame_data.json)\
                 , nor any Kubric sequence (metadata.json with segmentation_NNNNN.png and depth_NNNNN.tiff)"
                    .into(),
            ));
        };
        let mut scenes = RenderedScenes {
            dir: dir.to_path_buf(),
            format,
            scenes: Vec::new(),
            categories: Vec::new(),
            guides: BTreeMap::new(),
            far,
            notes: Vec::new(),
        };
        scenes.notes = scenes.format.notes();
        // Every scene's headers read in parallel; the first failure in order is reported.
        let indexed: Vec<Result<(ListedScene, SceneIndex)>> = found
            .into_par_iter()
            .map(|path| {
                let name = scenes.format.scene_name(&path);
                let index = scenes.format.index(&path).map_err(|e| scenes.refusal(&name, e))?;
                let scene =
                    ListedScene { name, path, width: index.width, height: index.height, prompt: index.prompt.clone() };
                Ok((scene, index))
            })
            .collect();
        let mut by_id: BTreeMap<u32, (Category, String)> = BTreeMap::new();
        let mut guides: BTreeMap<u32, (CategoryGuide, String)> = BTreeMap::new();
        for result in indexed {
            let (scene, index) = result?;
            for (id, guide) in index.guides {
                match guides.get(&id) {
                    Some((known, first)) if *known != guide => {
                        return Err(refuse(format!(
                            "category {id} is generated with {known:?} in {first} and {guide:?} in {}",
                            scene.name
                        )))
                    }
                    Some(_) => {}
                    None => {
                        guides.insert(id, (guide, scene.name.clone()));
                    }
                }
            }
            for category in index.categories {
                match by_id.get(&category.id) {
                    Some((known, first)) if known.name != category.name => {
                        return Err(refuse(format!(
                            "category id {} is `{}` in {first} and `{}` in {}",
                            category.id, known.name, category.name, scene.name
                        )))
                    }
                    Some(_) => {}
                    None => {
                        by_id.insert(category.id, (category, scene.name.clone()));
                    }
                }
            }
            scenes.scenes.push(scene);
        }
        scenes.categories = by_id.into_values().map(|(c, _)| c).collect();
        scenes.guides = guides.into_iter().map(|(id, (g, _))| (id, g)).collect();
        Ok(scenes)
    }

    /// What opening the folder noticed that the user should hear: a frame left out, say.
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    fn refusal(&self, scene: &str, e: SceneError) -> Error {
        let what = scenes_setting(&self.dir).then(format!(": scene {scene}"));
        Error::Context(what, Box::new(e.into()))
    }
}

/// `--scenes DIR`, the start of every refusal of the folder.
fn scenes_setting(dir: &Path) -> Message {
    Message::setting("scenes").then(format!(" {}", dir.display()))
}

fn within(dir: &Path, e: SceneError) -> Error {
    Error::Context(scenes_setting(dir), Box::new(e.into()))
}

impl SceneSource for RenderedScenes {
    fn available(&self) -> Option<u64> {
        Some(self.scenes.len() as u64)
    }

    fn scene(&self, k: u64) -> SceneInfo<'_> {
        let s = &self.scenes[k as usize];
        SceneInfo { width: s.width, height: s.height, name: Some(&s.name), prompt: s.prompt.as_deref() }
    }

    fn frame(&self, k: u64, _seed: u64) -> Result<SourceFrame> {
        let scene = &self.scenes[k as usize];
        let refuse = |e| self.refusal(&scene.name, e);
        let raw = self.format.read(&scene.path).map_err(refuse)?;
        if (raw.width, raw.height) != (scene.width, scene.height) {
            return Err(refuse(SceneError::new(format!(
                "{}×{} now, {}×{} when the scenes were listed",
                raw.width, raw.height, scene.width, scene.height
            ))));
        }
        let (frame, shaded) = raw.into_frame(self.far, &self.categories).map_err(refuse)?;
        Ok(SourceFrame { frame, shaded })
    }

    fn categories(&self) -> Vec<Category> {
        self.categories.clone()
    }

    fn category_guides(&self) -> BTreeMap<u32, CategoryGuide> {
        self.guides.clone()
    }

    fn settings(&self) -> Map<String, Value> {
        Map::from_iter([
            ("scenes".to_string(), json!(self.dir.display().to_string())),
            ("scene-format".to_string(), json!(self.format.name())),
            ("scene-names".to_string(), json!(self.scenes.iter().map(|s| s.name.as_str()).collect::<Vec<_>>())),
            ("categories".to_string(), json!(self.categories)),
            ("far".to_string(), json!(self.far)),
        ])
    }
}
