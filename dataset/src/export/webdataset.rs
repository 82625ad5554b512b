//! WebDataset shards: `{split}-NNNNNN.tar`, each closed once it holds `--shard-size` bytes, a
//! sample per image under its key (`KEY.png`, `KEY.json` with its COCO entry and annotations,
//! `KEY.mask.png`, `KEY.depth.exr`), in POSIX ustar that `tarfile` and `webdataset` read.

use super::set::{FinishedSet, SetImage};
use super::staging::Staging;
use super::stem;
use crate::error::{Error, Result};
use serde_json::json;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;
use vkdiff_formats::Error as FileError;

/// Writes the shards; returns how many.
pub fn write(
    set: &FinishedSet,
    staging: &mut Staging,
    shard_bytes: u64,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<usize> {
    let (mut done, mut shards) = (0, 0);
    for split in set.splits() {
        let mut shard: Option<Shard> = None;
        let mut next = 0;
        for image in set.in_split(split) {
            if shard.is_none() {
                shard = Some(Shard::open(staging, &format!("{}-{next:06}.tar", split.name()))?);
                next += 1;
            }
            let tar = shard.as_mut().expect("opened above");
            for (name, bytes) in sample(set, image)? {
                tar.append(&name, &bytes)?;
            }
            if tar.bytes >= shard_bytes {
                shard.take().expect("open").close()?;
            }
            done += 1;
            progress(done, set.images.len());
        }
        if let Some(tar) = shard {
            tar.close()?;
        }
        shards += next;
    }
    Ok(shards)
}

/// One image's files, named as WebDataset groups them.
fn sample(set: &FinishedSet, image: &SetImage) -> Result<Vec<(String, Vec<u8>)>> {
    let key = stem(image.file_name());
    let read = |file: &str| {
        let path = set.dir.join(file);
        std::fs::read(&path).map_err(|e| Error::from(FileError::Io { path, source: e }))
    };
    let file = |k: &str| {
        image.entry[k].as_str().ok_or_else(|| Error::Config(format!("image {} has no {k}", image.entry["id"])))
    };
    let meta = json!({
        "image": image.entry,
        "annotations": image.annotations,
        "categories": set.categories,
        "split": image.split.name(),
    });
    Ok(vec![
        (format!("{key}.png"), read(image.file_name())?),
        (format!("{key}.json"), serde_json::to_vec(&meta).expect("JSON values serialise")),
        (format!("{key}.mask.png"), read(file("mask_file")?)?),
        (format!("{key}.depth.exr"), read(file("depth_file")?)?),
    ])
}

/// A tar file being written: 512-byte ustar headers, data padded to 512, two zero blocks last.
struct Shard {
    file: BufWriter<File>,
    path: PathBuf,
    bytes: u64,
}

impl Shard {
    fn open(staging: &Staging, name: &str) -> Result<Shard> {
        let (file, path) = staging.create(name)?;
        Ok(Shard { file, path, bytes: 0 })
    }

    fn append(&mut self, name: &str, data: &[u8]) -> Result<()> {
        let header = ustar_header(name, data.len() as u64)?;
        let pad = (512 - data.len() % 512) % 512;
        let written = (self.file.write_all(&header))
            .and_then(|_| self.file.write_all(data))
            .and_then(|_| self.file.write_all(&vec![0; pad]));
        written.map_err(|e| FileError::Io { path: self.path.clone(), source: e })?;
        self.bytes += (512 + data.len() + pad) as u64;
        Ok(())
    }

    fn close(mut self) -> Result<()> {
        let closed = self.file.write_all(&[0; 1024]).and_then(|_| self.file.flush());
        Ok(closed.map_err(|e| FileError::Io { path: self.path, source: e })?)
    }
}

/// A regular file's header: mode 0644, owner 0, time 0 (shards are reproducible).
fn ustar_header(name: &str, size: u64) -> Result<[u8; 512]> {
    if name.len() > 100 || !name.is_ascii() {
        return Err(Error::Config(format!("{name}: a tar member name must be ASCII, at most 100 bytes")));
    }
    let mut h = [0u8; 512];
    let mut put = |at: usize, bytes: &[u8]| h[at..at + bytes.len()].copy_from_slice(bytes);
    put(0, name.as_bytes());
    put(100, b"0000644\0");
    put(108, b"0000000\0");
    put(116, b"0000000\0");
    put(124, format!("{size:011o}\0").as_bytes());
    put(136, b"00000000000\0");
    put(148, b"        ");
    put(156, b"0");
    put(257, b"ustar\0");
    put(263, b"00");
    let sum: u32 = h.iter().map(|&b| b as u32).sum();
    h[148..156].copy_from_slice(format!("{sum:06o}\0 ").as_bytes());
    Ok(h)
}
