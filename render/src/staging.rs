//! Atomic output: a scene folder is written into a hidden staging folder beside its final place
//! and renamed into place once every file is complete, so a reader (or a resumed run) sees the
//! whole folder or none of it. Dropping an uncommitted staging folder deletes it.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::{RenderError, Result};

static NEXT: AtomicU64 = AtomicU64::new(0);

pub struct StagingDir {
    staging: PathBuf,
    target: PathBuf,
    committed: bool,
}

/// A hidden sibling of `target` that no other process or call uses.
fn sibling(target: &Path, tag: &str) -> Result<PathBuf> {
    let name = target.file_name().ok_or_else(|| RenderError::invalid("out", target.display(), "names no folder"))?;
    let unique =
        format!(".{}.{tag}-{}-{}", name.to_string_lossy(), std::process::id(), NEXT.fetch_add(1, Ordering::Relaxed));
    Ok(target.with_file_name(unique))
}

impl StagingDir {
    /// Creates the staging folder (and `target`'s parents); fails if `target` exists, unless
    /// `replace`.
    pub fn create(target: &Path, replace: bool) -> Result<StagingDir> {
        if !replace && target.exists() {
            return Err(RenderError::OutputExists { path: target.to_path_buf() });
        }
        let staging = sibling(target, "partial")?;
        let parent = staging.parent().unwrap_or(Path::new("."));
        std::fs::create_dir_all(parent).map_err(|e| RenderError::io("create folder", parent, e))?;
        std::fs::create_dir(&staging).map_err(|e| RenderError::io("write into folder", parent, e))?;
        Ok(StagingDir { staging, target: target.to_path_buf(), committed: false })
    }

    /// Writes `bytes` to `relative` inside the staging folder.
    pub fn write(&self, relative: &str, bytes: &[u8]) -> Result<()> {
        let path = self.staging.join(relative);
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir).map_err(|e| RenderError::io("create folder", dir, e))?;
        }
        std::fs::write(&path, bytes).map_err(|e| RenderError::io("write", self.target.join(relative), e))
    }

    /// Moves the folder into place; an existing target (allowed by `replace`) is moved aside
    /// first and deleted after.
    pub fn commit(mut self) -> Result<()> {
        let old = if self.target.exists() {
            let aside = sibling(&self.target, "old")?;
            std::fs::rename(&self.target, &aside).map_err(|e| RenderError::io("move aside", &self.target, e))?;
            Some(aside)
        } else {
            None
        };
        std::fs::rename(&self.staging, &self.target)
            .map_err(|e| RenderError::io("move into place", &self.target, e))?;
        self.committed = true;
        if let Some(old) = old {
            std::fs::remove_dir_all(&old).map_err(|e| RenderError::io("remove the replaced", &old, e))?;
        }
        Ok(())
    }
}

impl Drop for StagingDir {
    fn drop(&mut self) {
        if !self.committed {
            // Best effort: the folder is hidden and uniquely named, so a leftover harms nothing.
            let _ = std::fs::remove_dir_all(&self.staging);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("vkdiff-staging-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn nothing_appears_until_commit_and_a_dropped_stage_leaves_nothing() {
        let root = scratch("commit");
        let target = root.join("scene");
        let stage = StagingDir::create(&target, false).unwrap();
        stage.write("crops/0/a.txt", b"a").unwrap();
        assert!(!target.exists());
        stage.commit().unwrap();
        assert_eq!(std::fs::read(target.join("crops/0/a.txt")).unwrap(), b"a");
        assert!(matches!(StagingDir::create(&target, false), Err(RenderError::OutputExists { .. })));
        let replacing = StagingDir::create(&target, true).unwrap();
        replacing.write("b.txt", b"b").unwrap();
        drop(replacing);
        assert!(target.join("crops/0/a.txt").exists() && !target.join("b.txt").exists());
        let replacing = StagingDir::create(&target, true).unwrap();
        replacing.write("b.txt", b"b").unwrap();
        replacing.commit().unwrap();
        assert!(!target.join("crops").exists() && target.join("b.txt").exists());
        let names: Vec<_> = std::fs::read_dir(&root).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names, vec![std::ffi::OsString::from("scene")], "no staging leftovers");
        std::fs::remove_dir_all(root).unwrap();
    }
}
