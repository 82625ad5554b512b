//! Not filling the disk: the set's size estimated from the images written (from earlier runs'
//! records before the first), and before each image a check that the images left fit in the
//! free space with `--min-free` to spare, stopping cleanly with one line when they do not.
//! Shared cluster file systems are not ours to fill.

use super::folder::Dataset;
use crate::error::{Error, Result};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use vkdiff_formats::Error as FileError;
use vkdiff_setting::Message;

/// The default `--min-free`: 2 GiB.
pub const DEFAULT_MIN_FREE: u64 = 2 << 30;

/// What this run has written so far, shared between the writer and the loop that checks.
#[derive(Default, Debug)]
pub struct Written {
    bytes: AtomicU64,
    images: AtomicU64,
}

impl Written {
    pub fn add(&self, bytes: u64) {
        self.bytes.fetch_add(bytes, Ordering::Relaxed);
        self.images.fetch_add(1, Ordering::Relaxed);
    }
}

#[derive(Clone, Debug)]
pub struct DiskGuard {
    dir: PathBuf,
    min_free: u64,
    /// Bytes per image from earlier runs' records, and how many images that is.
    earlier: (u64, u64),
    pub written: Arc<Written>,
}

impl DiskGuard {
    /// A guard for `dataset`, whose images already done hold `done_bytes` in `done` images.
    pub fn new(dataset: &Dataset, min_free: u64, done_bytes: u64, done: u64) -> DiskGuard {
        DiskGuard { dir: dataset.dir.clone(), min_free, earlier: (done_bytes, done), written: Arc::default() }
    }

    /// Bytes per image: measured on this run's images, else on earlier runs'.
    pub fn per_image(&self) -> Option<f64> {
        let (bytes, images) = (self.written.bytes.load(Ordering::Relaxed), self.written.images.load(Ordering::Relaxed));
        let (bytes, images) = if images > 0 { (bytes, images) } else { self.earlier };
        (images > 0).then(|| bytes as f64 / images as f64)
    }

    /// The images of this run written so far.
    pub fn images_written(&self) -> u64 {
        self.written.images.load(Ordering::Relaxed)
    }

    /// Refuses, naming the sizes, when `remaining` images at the measured size and the margin
    /// do not fit in the free space (before any image is measured, the margin alone).
    pub fn check(&self, remaining: u64) -> Result<()> {
        let free = free_bytes(&self.dir)?;
        let per_image = self.per_image();
        let need = per_image.map_or(0.0, |b| b * remaining as f64) as u64;
        if free >= need.saturating_add(self.min_free) {
            return Ok(());
        }
        let what = match per_image {
            Some(per) => format!("the {remaining} images left need about {} ({} each)", size(need), size(per as u64)),
            None => "no image is measured yet".into(),
        };
        Err(refusal(&self.dir, free, &what, self.min_free))
    }
}

/// Refuses a run whose folder's file system has less than `min_free` free, before anything is
/// written (the folder itself may not exist yet: its nearest existing parent is asked).
pub fn check_margin(dir: &Path, min_free: u64) -> Result<()> {
    let existing = dir.ancestors().find(|p| p.exists()).unwrap_or(Path::new("."));
    let free = free_bytes(existing)?;
    if free >= min_free {
        return Ok(());
    }
    Err(refusal(dir, free, "nothing is written yet", min_free))
}

fn refusal(dir: &Path, free: u64, what: &str, min_free: u64) -> Error {
    Error::DiskFull(
        Message::text(format!(
            "stopped before filling the disk: {} has {} free; {what}, and ",
            dir.display(),
            size(free)
        ))
        .and("min_free")
        .then(format!(" keeps {}: free space or lower ", size(min_free)))
        .and("min_free")
        .then(", then run the same command to resume"),
    )
}

/// Space an unprivileged process may use on the file system holding `dir`.
pub fn free_bytes(dir: &Path) -> Result<u64> {
    let io = |e: std::io::Error| Error::from(FileError::Io { path: dir.to_path_buf(), source: e });
    let path = std::ffi::CString::new(dir.as_os_str().as_encoded_bytes())
        .map_err(|_| io(std::io::Error::other("a path with a NUL byte")))?;
    let mut stats = std::mem::MaybeUninit::<libc::statvfs>::uninit();
    // SAFETY: `path` is NUL-terminated and `stats` is written by the call before it is read.
    if unsafe { libc::statvfs(path.as_ptr(), stats.as_mut_ptr()) } != 0 {
        return Err(io(std::io::Error::last_os_error()));
    }
    // SAFETY: statvfs returned 0, so it filled `stats`.
    let stats = unsafe { stats.assume_init() };
    #[allow(clippy::unnecessary_cast)] // narrower than u64 on 32-bit targets
    Ok((stats.f_bavail as u64).saturating_mul(stats.f_frsize as u64))
}

/// Bytes as people read them: 1.5 GiB, 830 MiB, 12 KiB.
pub fn size(bytes: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut value = bytes as f64;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < UNITS.len() {
        value /= 1024.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{bytes} B")
    } else if value < 10.0 {
        format!("{value:.1} {}", UNITS[unit])
    } else {
        format!("{value:.0} {}", UNITS[unit])
    }
}

/// `--min-free`'s value: bytes, or a number with K, M, G or T (powers of 1024; `2G`, `1.5G`).
pub fn parse_size(text: &str) -> std::result::Result<u64, String> {
    let t = text.trim();
    let (number, shift) = match t.char_indices().last() {
        Some((i, c)) if c.is_ascii_alphabetic() => {
            let shift = match c.to_ascii_uppercase() {
                'K' => 10,
                'M' => 20,
                'G' => 30,
                'T' => 40,
                _ => return Err(format!("{text}: expected bytes or a number with K, M, G or T")),
            };
            (&t[..i], shift)
        }
        _ => (t, 0),
    };
    let value: f64 =
        number.trim().parse().map_err(|_| format!("{text}: expected bytes or a number with K, M, G or T"))?;
    if !value.is_finite() || value < 0.0 {
        return Err(format!("{text}: a size is a number of bytes, 0 or more"));
    }
    Ok((value * (1u64 << shift) as f64) as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_read_and_print_as_people_write_them() {
        assert_eq!(parse_size("2G"), Ok(2 << 30));
        assert_eq!(parse_size("1.5k"), Ok(1536));
        assert_eq!(parse_size("0"), Ok(0));
        assert!(parse_size("-1M").is_err() && parse_size("2Q").is_err() && parse_size("").is_err());
        assert_eq!(size(1536), "1.5 KiB");
        assert_eq!(size(3 << 30), "3.0 GiB");
        assert_eq!(size(800), "800 B");
        assert!(free_bytes(Path::new(".")).unwrap() > 0);
        assert!(free_bytes(Path::new("/no/such/folder")).is_err());
    }
}
