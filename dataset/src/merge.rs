//! `vkdiff dataset merge`: the records of every image, whichever shard made them, joined into one
//! COCO `annotations.json` in index order, annotation ids renumbered from 1 in that order. Refuses
//! while any image is missing or was made with other settings.

use super::folder::{Dataset, VersionChange, ANNOTATIONS};
use crate::error::{Error, Result};
use serde_json::json;
use std::path::Path;
use vkdiff_pipeline::files::write_atomic_with;

/// What a merge joined.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Merged {
    pub images: u64,
    pub annotations: u64,
}

/// Joins the records of the dataset in `dir` into `dir/annotations.json`, if this version made
/// the set or `versions` allows another.
pub fn merge(dir: &Path, versions: VersionChange) -> Result<Merged> {
    let dataset = Dataset::for_merge(dir, versions)?;
    let mut missing = Vec::new();
    let mut images = Vec::with_capacity(dataset.images as usize);
    let mut annotations = 0;
    for index in 0..dataset.images {
        match dataset.finished(index) {
            Ok(record) => {
                annotations += record.annotations.len() as u64;
                images.push(record.image);
            }
            Err(why) => missing.push((index, why)),
        }
    }
    if let Some((_, why)) = missing.iter().find(|(_, why)| why.is_some()) {
        return Err(Error::Config(format!("{}: {}", dir.display(), why.as_deref().unwrap_or_default())));
    }
    if !missing.is_empty() {
        let per = dataset.images_per_scene.max(1);
        let first: Vec<String> =
            missing.iter().take(5).map(|(i, _)| format!("image {i} (scene {})", i / per)).collect();
        return Err(Error::Config(format!(
            "{}: {} of {} images are not done yet ({}{}); run the shards that own them (vkdiff dataset with the same \
                settings) before merging",
            dir.display(),
            missing.len(),
            dataset.images,
            first.join(", "),
            if missing.len() > 5 { ", …" } else { "" }
        )));
    }
    let settings = &dataset.settings;
    let description = match settings["scenes"].as_str() {
        Some(dir) => format!("vkdiff dataset: scenes rendered elsewhere ({dir}), with their annotations"),
        None => "vkdiff dataset: procedural white button mushroom beds".into(),
    };
    let made = if settings["render-only"] == true { "as rendered" } else { "made photoreal by SDXL on Vulkan" };
    let head = json!({
        "info": {
            "description": format!("{description}, {made}"),
            "version": vkdiff_setting::version(),
            "fingerprint": dataset.fingerprint,
            "settings": dataset.settings,
        },
        "licenses": [],
        "categories": dataset.categories(),
    });
    // Streamed: a large set's annotations need not fit in memory at once.
    write_atomic_with(&dir.join(ANNOTATIONS), &mut |w| {
        let head = serde_json::to_string(&head)?;
        w.write_all(&head.as_bytes()[..head.len() - 1])?;
        w.write_all(b",\"images\":")?;
        serde_json::to_writer(&mut *w, &images)?;
        w.write_all(b",\"annotations\":[")?;
        let mut id = 0u64;
        for index in 0..dataset.images {
            let record = dataset.finished(index).map_err(|why| {
                std::io::Error::other(why.unwrap_or_else(|| format!("image {index} vanished during the merge")))
            })?;
            for mut annotation in record.annotations {
                id += 1;
                annotation.id = Some(id);
                w.write_all(if id == 1 { b"" } else { b"," })?;
                serde_json::to_writer(&mut *w, &annotation.sorted_json())?;
            }
        }
        w.write_all(b"]}\n")
    })?;
    dataset.remove_partials(&|_| true)?;
    Ok(Merged { images: dataset.images, annotations })
}
