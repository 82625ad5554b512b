//! vkdiff's scene sources: where a dataset's scenes come from, behind one trait, [`SceneSource`].
//! The procedural mushroom bed draws as many as asked; scenes rendered elsewhere (`--scenes DIR`:
//! scene folders in the format `vkdiff scene` writes, BlenderProc's `.hdf5` files, BOP scenes, Replicator's BasicWriter frames, Unity Perception's SOLO datasets, or Kubric's sequences) are listed
//! and checked from their headers and side files, and each scene's pixels are read once, when its
//! images are made. Each source gives, for scene k, a [`Frame`] (depth, instance ids, each
//! instance's category and attributes) and perhaps the renderer's own image; everything after
//! (crops, control images, generation, annotations, exports) knows categories as data.

mod blenderproc;
mod bop;
mod bop_geometry;
mod folder;
mod folder_geometry;
mod format;
mod kubric;
mod kubric_geometry;
mod kubric_metadata;
mod labels;
mod procedural;
mod rendered;
mod replicator;
mod replicator_boxes;
mod replicator_camera;
mod replicator_files;
mod solo;
mod solo_geometry;
mod solo_step;

use serde_json::{Map, Value};
use std::collections::BTreeMap;
use std::path::Path;
use vkdiff_render::coco::Category;
use vkdiff_render::frame::Frame;
use vkdiff_setting::Message;

pub use folder::is_scene_folder;
pub use labels::CategoryGuide;
pub use procedural::ProceduralBed;
pub use rendered::RenderedScenes;

/// Where a dataset's scenes come from. Scene `k` is drawn with seed `seed` where the source draws
/// its scenes; a source that holds a fixed number lists them in a fixed order.
pub trait SceneSource: Send + Sync + std::fmt::Debug {
    /// The scenes there are; None for a source that draws as many as asked.
    fn available(&self) -> Option<u64>;

    /// What is known of scene `k` before its pixels are read: its size, name and prompt.
    fn scene(&self, k: u64) -> SceneInfo<'_>;

    /// Scene `k`'s frame, and the renderer's image of it where it gave one: its pixels, read (or
    /// rendered) now.
    fn frame(&self, k: u64, seed: u64) -> Result<SourceFrame>;

    /// The categories of the set, by id.
    fn categories(&self) -> Vec<Category>;

    /// How the source says categories are generated (a prompt, a strength), by id.
    fn category_guides(&self) -> BTreeMap<u32, CategoryGuide> {
        BTreeMap::new()
    }

    /// The source's settings, under their flags' names, as dataset.json records them.
    fn settings(&self) -> Map<String, Value>;
}

/// One scene as its source lists it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneInfo<'a> {
    pub width: u32,
    pub height: u32,
    /// Its folder's or file's name, for its images' COCO entries.
    pub name: Option<&'a str>,
    /// Its own prompt (prompt.txt).
    pub prompt: Option<&'a str>,
}

/// One scene's frame, and the renderer's image of it (RGB, the frame's size) where it gave one.
pub struct SourceFrame {
    pub frame: Frame,
    pub shaded: Option<Vec<u8>>,
}

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

/// Why the rendered scenes, or one of them, cannot be used; the source prefixes the folder and
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

/// `why`, about the file `file` of the scene being read, named as its scene folder names it (the
/// refusal around it names the scene).
pub(crate) fn bad(file: &str, why: impl std::fmt::Display) -> SceneError {
    SceneError::new(format!("{file}: {why}"))
}

/// A reader's error about the file `name`, as [`bad`] words it ("missing" where it is not there).
pub(crate) fn file_error(name: &str) -> impl Fn(vkdiff_formats::Error) -> SceneError + '_ {
    move |e| match e {
        vkdiff_formats::Error::Io { source, .. } if source.kind() == std::io::ErrorKind::NotFound => {
            bad(name, "missing")
        }
        vkdiff_formats::Error::Io { source, .. } => bad(name, source),
        vkdiff_formats::Error::Format { why, .. } => bad(name, why),
        vkdiff_formats::Error::Tensor(why) => bad(name, why),
    }
}

/// Background depth the renderers write as a far value (BlenderProc: 1e10) rather than ∞: depth
/// at or past this many metres (or units) is background, unless `--far` says otherwise.
pub const DEFAULT_FAR: f32 = 1e4;
