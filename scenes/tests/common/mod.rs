//! What the reader tests of the scene formats share: the fixtures' folder, their JSON, and the
//! refusal of a broken folder.

use serde_json::Value;
use std::path::{Path, PathBuf};
use vkdiff_scenes::{RenderedScenes, SceneSource, DEFAULT_FAR};

pub fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/scenes")
}

pub fn json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// When a broken folder is refused: as it is listed, or as the broken scene is read.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum When {
    Listed,
    Read,
}

/// The refusal of the folder `dir` (`fault` names it in failures), which must come `when` said
/// and be one line.
pub fn refusal(dir: &Path, fault: &str, when: When) -> String {
    let (got, refused) = match RenderedScenes::open(dir, "object", DEFAULT_FAR) {
        Err(e) => (When::Listed, e.to_string()),
        Ok(scenes) => {
            let e = (0..scenes.available().unwrap()).find_map(|k| scenes.frame(k, 0).err());
            (When::Read, e.unwrap_or_else(|| panic!("{fault}: read whole")).to_string())
        }
    };
    assert_eq!(got, when, "{fault}: {refused}");
    assert!(!refused.contains('\n'), "{fault}: {refused}");
    refused
}
