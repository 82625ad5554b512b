//! Output files that appear whole or not at all: written under a hidden temporary name beside
//! their place, flushed to the disk, then renamed. A crash, a kill or a power cut leaves the old
//! file or the new one, never a part, and at worst a hidden `.NAME.partial-…` that a later run
//! removes.

use crate::error::{Error, Result};
use std::io::Write;
use std::path::{Path, PathBuf};

/// A temporary name for `path`, unique to this write: processes on several machines may write
/// the same shared file (the manifest, the merged annotations) at once.
pub fn partial_path(path: &Path) -> PathBuf {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos());
    let n = WRITES.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    path.with_file_name(format!(".{name}{PARTIAL}{}-{nanos:x}-{n}", std::process::id()))
}

static WRITES: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// What marks a temporary file: `.NAME.partial-…`.
pub const PARTIAL: &str = ".partial-";

/// Writes `bytes` to `path` atomically and durably; on failure nothing is left behind.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic_all(&[(path, bytes)])
}

/// [`write_atomic`] of what `fill` writes (for files too large to hold in memory whole).
pub fn write_atomic_with(path: &Path, fill: &mut dyn FnMut(&mut dyn Write) -> std::io::Result<()>) -> Result<()> {
    let tmp = partial_path(path);
    let written = (|| {
        let mut file = std::io::BufWriter::new(std::fs::File::create(&tmp)?);
        fill(&mut file)?;
        let file = file.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written.map_err(|e| Error::Io { path: path.to_path_buf(), source: e })
}

/// Writes several files that belong together: all or none. Each is written whole under its
/// temporary name first; only then are they renamed, and a failed rename takes back the files
/// already renamed.
pub fn write_atomic_all(files: &[(&Path, &[u8])]) -> Result<()> {
    let mut temporary = Vec::new();
    let remove = |paths: &[PathBuf]| paths.iter().for_each(|p| drop(std::fs::remove_file(p)));
    for (path, bytes) in files {
        let tmp = partial_path(path);
        let written = (|| {
            let mut file = std::fs::File::create(&tmp)?;
            file.write_all(bytes)?;
            file.sync_all()
        })();
        temporary.push(tmp);
        if let Err(e) = written {
            remove(&temporary);
            return Err(Error::Io { path: path.to_path_buf(), source: e });
        }
    }
    for (i, ((path, _), tmp)) in files.iter().zip(&temporary).enumerate() {
        if let Err(e) = std::fs::rename(tmp, path) {
            remove(&temporary[i..]);
            let placed: Vec<PathBuf> = files[..i].iter().map(|(p, _)| p.to_path_buf()).collect();
            remove(&placed);
            return Err(Error::Io { path: path.to_path_buf(), source: e });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_write_appears_whole_and_a_failed_one_leaves_nothing() {
        let dir = std::env::temp_dir().join(format!("vkdiff-files-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("a.json");
        write_atomic(&path, b"one").unwrap();
        write_atomic(&path, b"two").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"two");
        let failed = write_atomic_with(&path, &mut |w| {
            w.write_all(b"half")?;
            Err(std::io::Error::other("disk full"))
        });
        assert!(failed.unwrap_err().to_string().contains("disk full"));
        assert_eq!(std::fs::read(&path).unwrap(), b"two", "the old file stays");
        let names: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names, vec![std::ffi::OsString::from("a.json")], "no temporary file left");
        assert_ne!(partial_path(&path), partial_path(&path), "every write has its own temporary name");
        std::fs::remove_dir_all(dir).unwrap();
    }
}
