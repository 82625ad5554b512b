//! Paths of the repository's fixtures (written by the scripts in `tools/`) and scratch space.

use std::path::PathBuf;

/// `path` relative to the repository root.
pub fn repo(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..").join(path)
}

/// `tests/fixtures/<path>`.
pub fn fixture(path: &str) -> PathBuf {
    repo("tests/fixtures").join(path)
}

/// An empty folder of this process for one test's files (`name` tells tests apart).
pub fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("vkdiff-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}
