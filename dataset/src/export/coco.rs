//! COCO with splits: `train.json`, `val.json`, `test.json`, each a whole COCO file of its
//! images, beside the set's files under their own relative paths (so every `*_file` an entry
//! names resolves from OUT, as `file_name` does for Detectron2's `image_root`).

use super::set::FinishedSet;
use super::staging::Staging;
use crate::error::Result;
use serde_json::json;
use std::io::Write;
use vkdiff_formats::Error as FileError;

pub fn write(set: &FinishedSet, staging: &mut Staging, progress: &mut dyn FnMut(usize, usize)) -> Result<()> {
    for (done, image) in set.images.iter().enumerate() {
        for (_, file) in image.files() {
            staging.link(&set.dir.join(file), file)?;
        }
        progress(done + 1, set.images.len());
    }
    for split in set.splits() {
        let images: Vec<_> = set.in_split(split).collect();
        let coco = json!({
            "info": set.info_of(split),
            "licenses": set.licenses,
            "categories": set.categories,
            "images": images.iter().map(|i| &i.entry).collect::<Vec<_>>(),
            "annotations": images.iter().flat_map(|i| &i.annotations).collect::<Vec<_>>(),
        });
        let (mut file, path) = staging.create(&format!("{}.json", split.name()))?;
        serde_json::to_writer(&mut file, &coco)
            .map_err(std::io::Error::from)
            .and_then(|_| file.write_all(b"\n"))
            .and_then(|_| file.flush())
            .map_err(|e| FileError::Io { path, source: e })?;
    }
    Ok(())
}
