//! vkdiff's scene sources. Where a dataset's scenes come from, behind one interface: the procedural mushroom bed, or
//! scenes rendered elsewhere (`--scenes DIR`: scene folders in the format `vkdiff scene` writes,
//! or BlenderProc's `.hdf5` files). Each gives, for scene k, a [`Frame`] (depth, instance ids,
//! each instance's category and attributes) and perhaps the renderer's own image; everything
//! after (crops, control images, generation, annotations, exports) knows categories as data.

mod blenderproc;
mod folder;
mod labels;

use rayon::prelude::*;
use serde_json::{json, Map, Value};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use vkdiff_render::coco::{mushroom_category, Category};
use vkdiff_render::frame::Frame;
use vkdiff_render::scene::{Scene, SceneConfig};
use vkdiff_setting::Message;

pub use folder::is_scene_folder;

/// What reading scenes can fail with: a setting refused, a scene that cannot be used (prefixed
/// by the folder and the scene), or the procedural bed's own refusal.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A setting refused, every setting it names kept as data.
    #[error("{0}")]
    Setting(Message),
    /// An error prefixed by what it happened to (the setting and its folder, the scene).
    #[error("{0}: {1}")]
    Context(Message, Box<Error>),
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Render(#[from] vkdiff_render::RenderError),
}

pub type Result<T> = std::result::Result<T, Error>;

/// Why the rendered scenes, or one of them, cannot be used; the scan prefixes the folder and
/// the scene. A file is named as it is in its scene folder.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The folder of scenes cannot be listed.
    #[error("{0}")]
    Listing(std::io::Error),
    /// A file of the scene that cannot be read.
    #[error("{name}: {source}")]
    Io { name: String, source: std::io::Error },
    /// What the scene holds that cannot be used: a malformed file, sizes or categories that
    /// disagree.
    #[error("{0}")]
    Invalid(String),
}

/// A file's name in its scene folder.
fn name_of(path: &Path) -> String {
    path.file_name().map_or(path.display().to_string(), |n| n.to_string_lossy().into_owned())
}

impl SceneError {
    fn new(why: String) -> SceneError {
        SceneError::Invalid(why)
    }

    /// `why`, about the file `path` of the scene.
    fn file(path: &Path, why: String) -> SceneError {
        SceneError::Invalid(format!("{}: {why}", name_of(path)))
    }

    fn io(path: &Path, source: std::io::Error) -> SceneError {
        SceneError::Io { name: name_of(path), source }
    }

    fn from_file(e: vkdiff_formats::Error) -> SceneError {
        match e {
            vkdiff_formats::Error::Io { path, source } => SceneError::io(&path, source),
            vkdiff_formats::Error::Format { path, why } => SceneError::file(&path, why),
            vkdiff_formats::Error::Tensor(why) => SceneError::Invalid(why),
        }
    }
}

/// Background depth the renderers write as a far value (BlenderProc: 1e10) rather than ∞: depth
/// at or past this many metres (or units) is background, unless `--far` says otherwise.
pub const DEFAULT_FAR: f32 = 1e4;

/// How scenes rendered elsewhere are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RenderedFormat {
    /// One folder per scene (depth, instances.png, categories.json, …).
    Folders,
    /// BlenderProc's `write_hdf5`: one `<frame>.hdf5` per scene.
    BlenderProc,
}

impl RenderedFormat {
    fn name(self) -> &'static str {
        match self {
            RenderedFormat::Folders => "scene folders",
            RenderedFormat::BlenderProc => "blenderproc hdf5",
        }
    }
}

/// One rendered scene, as the scan found it.
#[derive(Clone, Debug)]
pub struct RenderedScene {
    /// The folder's or file's name.
    pub name: String,
    pub path: PathBuf,
    pub width: u32,
    pub height: u32,
    /// prompt.txt's text.
    pub prompt: Option<String>,
    /// Whether the renderer's own image is there (shaded.png, BlenderProc's `colors`).
    pub shaded: bool,
}

/// Scenes rendered elsewhere, every one of them read and checked.
#[derive(Clone, Debug)]
pub struct RenderedScenes {
    pub dir: PathBuf,
    pub format: RenderedFormat,
    pub scenes: Vec<RenderedScene>,
    /// Every category the scenes use, by id.
    pub categories: Vec<Category>,
    /// The category of scene folders with no categories.json (`--category`).
    pub default_category: Category,
    pub far: f32,
}

/// Where scenes come from.
#[derive(Clone, Debug)]
pub enum SceneSource {
    Procedural(SceneConfig),
    Rendered(RenderedScenes),
}

/// One scene's frame, and the renderer's image of it (RGB, the frame's size) where it gave one.
pub struct SourceFrame {
    pub frame: Frame,
    pub shaded: Option<Vec<u8>>,
}

impl SceneSource {
    /// The scenes there are, for a source that holds a fixed number.
    pub fn available(&self) -> Option<u64> {
        match self {
            SceneSource::Procedural(_) => None,
            SceneSource::Rendered(r) => Some(r.scenes.len() as u64),
        }
    }

    /// Scene `scene`'s frame size.
    pub fn frame_size(&self, scene: u64) -> (u32, u32) {
        match self {
            SceneSource::Procedural(c) => (c.width, c.height),
            SceneSource::Rendered(r) => {
                let s = &r.scenes[scene as usize];
                (s.width, s.height)
            }
        }
    }

    /// What to call scene `scene` in a message: its folder or file, or its seed.
    pub fn describe(&self, scene: u64, seed: u64) -> String {
        match self {
            SceneSource::Procedural(_) => format!("scene {scene} (seed {seed})"),
            SceneSource::Rendered(r) => format!("scene {}", r.scenes[scene as usize].path.display()),
        }
    }

    /// Scene `scene` (seeded by `seed` where the source draws it).
    pub fn frame(&self, scene: u64, seed: u64) -> Result<SourceFrame> {
        match self {
            SceneSource::Procedural(config) => {
                Ok(SourceFrame { frame: Scene::build(seed, config)?.render(), shaded: None })
            }
            SceneSource::Rendered(r) => {
                let (raw, _, _) = r.read(&r.scenes[scene as usize])?;
                let (frame, shaded) =
                    raw.into_frame(r.far).map_err(|e| r.refusal(&r.scenes[scene as usize].name, e))?;
                Ok(SourceFrame { frame, shaded })
            }
        }
    }

    /// Scene `scene`'s own prompt (prompt.txt).
    pub fn prompt(&self, scene: u64) -> Option<&str> {
        match self {
            SceneSource::Procedural(_) => None,
            SceneSource::Rendered(r) => r.scenes[scene as usize].prompt.as_deref(),
        }
    }

    /// Scene `scene`'s name in the source (folder or file), for its images' COCO entries.
    pub fn scene_name(&self, scene: u64) -> Option<&str> {
        match self {
            SceneSource::Procedural(_) => None,
            SceneSource::Rendered(r) => Some(&r.scenes[scene as usize].name),
        }
    }

    /// The categories of the set, by id.
    pub fn categories(&self) -> Vec<Category> {
        match self {
            SceneSource::Procedural(_) => vec![mushroom_category()],
            SceneSource::Rendered(r) => r.categories.clone(),
        }
    }

    /// The source's settings, under their flags' names, as dataset.json records them.
    pub fn to_json(&self) -> Map<String, Value> {
        let value = match self {
            SceneSource::Procedural(c) => json!({
                "width": c.width,
                "height": c.height,
                "density": c.bed.density,
                "clumping": c.bed.clumping.clustered_fraction,
            }),
            SceneSource::Rendered(r) => json!({
                "scenes": r.dir.display().to_string(),
                "scene-format": r.format.name(),
                "scene-names": r.scenes.iter().map(|s| s.name.as_str()).collect::<Vec<_>>(),
                "categories": r.categories,
                "far": r.far,
            }),
        };
        match value {
            Value::Object(map) => map,
            _ => unreachable!("built from an object literal"),
        }
    }
}

impl RenderedScenes {
    /// Finds and reads every scene under `dir` (scene folders, else BlenderProc `.hdf5` files),
    /// in name order, and checks each: a missing or unreadable file, sizes that differ, an
    /// instance without a category, a category listed twice or named two ways is refused in one
    /// line naming the scene.
    pub fn scan(dir: &Path, default_category: &str, far: f32) -> Result<RenderedScenes> {
        let refuse =
            |why: String| Error::Setting(Message::setting("scenes").then(format!(" {}: {why}", dir.display())));
        let within = |e: SceneError| {
            Error::Context(Message::setting("scenes").then(format!(" {}", dir.display())), Box::new(e.into()))
        };
        if !(far.is_finite() && far > 0.0) {
            return Err(Error::Setting(Message::setting("far").then(format!(" {far} must be a positive number"))));
        }
        if default_category.trim().is_empty() {
            return Err(Error::Setting(Message::setting("category").then(" must name the category")));
        }
        let entries = std::fs::read_dir(dir).map_err(|e| within(SceneError::Listing(e)))?;
        let mut paths: Vec<PathBuf> = entries.flatten().map(|e| e.path()).collect();
        paths.sort();
        let hdf5: Vec<PathBuf> =
            paths.iter().filter(|p| p.extension().is_some_and(|e| e == "hdf5" || e == "h5")).cloned().collect();
        let folders: Vec<PathBuf> = paths.iter().filter(|p| p.is_dir() && !is_hidden(p)).cloned().collect();
        let (format, mut found) =
            match (hdf5.is_empty(), folders.iter().any(|f| is_scene_folder(f))) {
                (false, _) => (RenderedFormat::BlenderProc, hdf5),
                (true, true) => (RenderedFormat::Folders, folders),
                (true, false) => return Err(refuse(
                    "holds no scene folders (each with depth.exr or depth.png and instances.png) and no BlenderProc \
                     .hdf5 files"
                        .into(),
                )),
            };
        if format == RenderedFormat::BlenderProc {
            // BlenderProc numbers its frames 0.hdf5, 1.hdf5, …, 10.hdf5: in number order.
            found.sort_by_key(|p| (stem_number(p), p.clone()));
        }
        let default =
            Category { id: 1, name: default_category.trim().into(), supercategory: default_category.trim().into() };
        let names = match format {
            RenderedFormat::BlenderProc if dir.join("categories.json").is_file() => {
                let (categories, _) = folder::read_categories(&dir.join("categories.json")).map_err(within)?;
                Some(categories)
            }
            _ => None,
        };
        let mut scenes = RenderedScenes {
            dir: dir.to_path_buf(),
            format,
            scenes: Vec::new(),
            categories: Vec::new(),
            default_category: default,
            far,
        };
        let names_of = |p: &PathBuf| p.file_name().map_or(String::new(), |n| n.to_string_lossy().into_owned());
        let listed: Vec<RenderedScene> = found
            .iter()
            .map(|p| RenderedScene {
                name: names_of(p),
                path: p.clone(),
                width: 0,
                height: 0,
                prompt: None,
                shaded: false,
            })
            .collect();
        // Every scene read in full, in parallel; the first failure in name order is reported.
        let checked: Vec<Result<(RenderedScene, Vec<Category>)>> = listed
            .into_par_iter()
            .map(|mut scene| {
                let (raw, categories, prompt) = scenes.read(&scene)?;
                scene.width = raw.width;
                scene.height = raw.height;
                scene.prompt = prompt;
                scene.shaded = raw.shaded.is_some();
                let name = scene.name.clone();
                raw.into_frame(far).map_err(|e| scenes.refusal(&name, e))?;
                Ok((scene, categories))
            })
            .collect();
        let mut by_id: BTreeMap<u32, (Category, String)> = BTreeMap::new();
        for result in checked {
            let (scene, categories) = result?;
            for category in categories {
                let category = match (&names, format) {
                    (Some(named), _) => named.iter().find(|c| c.id == category.id).cloned().unwrap_or(category),
                    _ => category,
                };
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
        Ok(scenes)
    }

    /// Reads one scene: its pixels, the categories it names, its prompt.
    fn read(&self, scene: &RenderedScene) -> Result<(labels::RawScene, Vec<Category>, Option<String>)> {
        let read = match self.format {
            RenderedFormat::Folders => folder::read_folder(&scene.path, &self.default_category),
            RenderedFormat::BlenderProc => blenderproc::read_hdf5(&scene.path).map(|(raw, used)| {
                let categories = used.into_iter().map(|id| self.blenderproc_category(id)).collect();
                (raw, categories, None)
            }),
        };
        read.map_err(|e| self.refusal(&scene.name, e))
    }

    /// A BlenderProc category id's name: from categories.json beside the files, else `category_<id>`.
    fn blenderproc_category(&self, id: u32) -> Category {
        let name = format!("category_{id}");
        Category { id, name: name.clone(), supercategory: name }
    }

    fn refusal(&self, scene: &str, e: SceneError) -> Error {
        let what = Message::setting("scenes").then(format!(" {}: scene {scene}", self.dir.display()));
        Error::Context(what, Box::new(e.into()))
    }
}

fn is_hidden(path: &Path) -> bool {
    path.file_name().is_some_and(|n| n.to_string_lossy().starts_with('.'))
}

/// A file's stem as a number (`12.hdf5` → 12), else past every number.
fn stem_number(path: &Path) -> u64 {
    path.file_stem().and_then(|s| s.to_str()).and_then(|s| s.parse().ok()).unwrap_or(u64::MAX)
}
