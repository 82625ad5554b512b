//! The export's folder while it is written: a hidden sibling of OUT, renamed to OUT once whole
//! (a killed export leaves only the hidden folder, never an OUT that looks finished).

use crate::error::Result;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use vkdiff_formats::Error as FileError;
use vkdiff_pipeline::files::PARTIAL;

pub struct Staging {
    root: PathBuf,
    copy: bool,
    pub copied: u64,
    pub linked: u64,
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> FileError + '_ {
    move |e| FileError::Io { path: path.to_path_buf(), source: e }
}

/// Removes the hidden folders that exports to the same OUT left when they were killed (their
/// process is gone; a running one's is kept).
fn remove_killed_exports(parent: &Path, name: &str) {
    let Ok(entries) = std::fs::read_dir(parent) else { return };
    for entry in entries.flatten() {
        let file = entry.file_name().to_string_lossy().into_owned();
        let pid = [PARTIAL, ".old-"].iter().find_map(|tag| file.strip_prefix(&format!(".{name}{tag}")));
        if pid.and_then(|p| p.parse::<u32>().ok()).is_some_and(|p| !Path::new(&format!("/proc/{p}")).exists()) {
            let _ = std::fs::remove_dir_all(entry.path());
        }
    }
}

impl Staging {
    /// A fresh hidden folder beside `out`; `copy`: copy files rather than hard-link them.
    pub fn beside(out: &Path, copy: bool) -> Result<Staging> {
        let parent = out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        let name = out.file_name().map_or("export".into(), |n| n.to_string_lossy().into_owned());
        let root = parent.join(format!(".{name}{PARTIAL}{}", std::process::id()));
        remove_killed_exports(parent, &name);
        let _ = std::fs::remove_dir_all(&root);
        std::fs::create_dir_all(&root).map_err(io(&root))?;
        Ok(Staging { root, copy, copied: 0, linked: 0 })
    }

    /// Where `relative` goes, its folder made.
    fn place(&self, relative: &str) -> Result<PathBuf> {
        let path = self.root.join(relative);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(io(parent))?;
        }
        Ok(path)
    }

    pub fn folder(&self, relative: &str) -> Result<()> {
        let path = self.root.join(relative);
        Ok(std::fs::create_dir_all(&path).map_err(io(&path))?)
    }

    pub fn write(&self, relative: &str, bytes: &[u8]) -> Result<()> {
        let path = self.place(relative)?;
        Ok(std::fs::write(&path, bytes).map_err(io(&path))?)
    }

    /// A file to stream into, with what to name in its errors.
    pub fn create(&self, relative: &str) -> Result<(BufWriter<File>, PathBuf)> {
        let path = self.place(relative)?;
        let file = File::create(&path).map_err(io(&path))?;
        Ok((BufWriter::new(file), path))
    }

    /// `source` at `relative`: hard-linked (the set's files are written once and never
    /// changed), or copied with `--copy` or where no link can reach (another file system).
    pub fn link(&mut self, source: &Path, relative: &str) -> Result<()> {
        let path = self.place(relative)?;
        if !self.copy && std::fs::hard_link(source, &path).is_ok() {
            self.linked += 1;
            return Ok(());
        }
        std::fs::copy(source, &path).map_err(io(source))?;
        self.copied += 1;
        Ok(())
    }

    /// Removes what was written.
    pub fn abandon(self) {
        let _ = std::fs::remove_dir_all(&self.root);
    }

    /// Renames the folder to `out`, replacing an existing `out` (which the caller allowed).
    pub fn publish(self, out: &Path, replace: bool) -> Result<()> {
        let old = self.root.with_file_name(format!(
            ".{}.old-{}",
            out.file_name().map_or("export".into(), |n| n.to_string_lossy()),
            std::process::id()
        ));
        if replace && out.exists() {
            if let Err(e) = std::fs::rename(out, &old) {
                self.abandon();
                return Err(io(out)(e).into());
            }
        }
        if let Err(e) = std::fs::rename(&self.root, out) {
            let _ = std::fs::rename(&old, out);
            self.abandon();
            return Err(io(out)(e).into());
        }
        let _ = std::fs::remove_dir_all(&old);
        Ok(())
    }
}
