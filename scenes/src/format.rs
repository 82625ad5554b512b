//! What every way of storing scenes answers: what a scene's headers and side files say, and its
//! pixels.

use crate::labels::{CategoryGuide, RawScene};
use crate::SceneError;
use std::collections::BTreeMap;
use std::path::Path;
use vkdiff_render::coco::Category;

/// One way scenes are stored: what each scene says of itself before its pixels are read, and its
/// pixels. (Each format finds its own scenes in a folder, `find`, before one is made.)
pub(crate) trait SceneFormat: Send + Sync + std::fmt::Debug {
    /// The format's name in dataset.json.
    fn name(&self) -> &'static str;

    /// A scene's name, as its images' COCO entries record it: its folder's or file's name.
    fn scene_name(&self, path: &Path) -> String {
        path.file_name().map_or(String::new(), |n| n.to_string_lossy().into_owned())
    }

    /// What a scene's headers and side files say: its size, prompt and categories.
    fn index(&self, path: &Path) -> Result<SceneIndex, SceneError>;

    /// The scene's pixels.
    fn read(&self, path: &Path) -> Result<RawScene, SceneError>;

    /// What opening the folder noticed that the user should hear (a frame left out).
    fn notes(&self) -> Vec<String> {
        Vec::new()
    }
}

/// A scene as its headers and side files describe it.
pub(crate) struct SceneIndex {
    pub width: u32,
    pub height: u32,
    pub prompt: Option<String>,
    /// The categories the scene names (a scene folder's categories.json, BlenderProc's category
    /// ids with their names).
    pub categories: Vec<Category>,
    /// What the scene's categories.json says of how categories are generated, by id.
    pub guides: BTreeMap<u32, CategoryGuide>,
}
