//! A Hugging Face image folder: `{train,validation,test}/NAME.png` with a `metadata.jsonl` in
//! each, one line per image: its COCO entry's fields (`id` as `image_id`) and its instances
//! under `objects` as HF's object-detection sets hold them (`bbox` as COCO's [x, y, w, h],
//! `category` the index of its category in annotations.json's list), with each instance's COCO
//! RLE mask under `segmentation` and its id in the instance mask under `mask_id`. The instance
//! mask is a second image column, `mask` (`mask_file_name`, `masks/NAME.png`: 16-bit ids, as
//! `datasets` 3 and later load them). README.md's card names the categories (`hf_card.rs`).

use super::set::FinishedSet;
use super::splits::Split;
use super::staging::Staging;
use crate::error::Result;
use serde_json::{json, Value};
use std::io::Write;
use vkdiff_formats::Error as FileError;

/// The folder names `load_dataset("imagefolder")` takes as splits.
fn folder(split: Split) -> &'static str {
    match split {
        Split::Train => "train",
        Split::Val => "validation",
        Split::Test => "test",
    }
}

pub fn write(set: &FinishedSet, staging: &mut Staging, progress: &mut dyn FnMut(usize, usize)) -> Result<()> {
    let classes: Vec<Value> =
        set.categories.as_array().map_or(Vec::new(), |c| c.iter().map(|c| c["id"].clone()).collect());
    let names: Vec<String> = set
        .categories
        .as_array()
        .map_or(Vec::new(), |c| c.iter().map(|c| c["name"].as_str().unwrap_or_default().to_string()).collect());
    let (mut rows, mut splits) = (Vec::new(), Vec::new());
    let mut done = 0;
    // `datasets` refuses a split folder without images: a split no scene fell in is left out.
    for split in set.splits().into_iter().filter(|&s| set.in_split(s).next().is_some()) {
        splits.push(folder(split));
        let (mut metadata, path) = staging.create(&format!("{}/metadata.jsonl", folder(split)))?;
        for image in set.in_split(split) {
            let name = image.file_name().rsplit('/').next().unwrap_or_default();
            staging.link(&set.dir.join(image.file_name()), &format!("{}/{name}", folder(split)))?;
            let mut row = json!({ "file_name": name, "image_id": image.entry["id"] });
            if let Some(mask) = image.entry["mask_file"].as_str() {
                let mask_name = format!("masks/{}", mask.rsplit('/').next().unwrap_or_default());
                staging.link(&set.dir.join(mask), &format!("{}/{mask_name}", folder(split)))?;
                row["mask_file_name"] = json!(mask_name);
            }
            for (key, value) in image.entry.as_object().expect("checked when read") {
                if key != "id" && key != "file_name" && !key.ends_with("_file") {
                    row[key] = value.clone();
                }
            }
            let field = |k: &str| image.annotations.iter().map(|a| a[k].clone()).collect::<Vec<_>>();
            let categories: Vec<Option<usize>> =
                image.annotations.iter().map(|a| classes.iter().position(|c| *c == a["category_id"])).collect();
            row["objects"] = json!({
                "id": field("id"),
                "area": field("area"),
                "bbox": field("bbox"),
                "category": categories,
                "iscrowd": field("iscrowd"),
                "mask_id": field("mask_id"),
                "segmentation": field("segmentation"),
            });
            let line = serde_json::to_string(&row).expect("JSON values serialise");
            writeln!(metadata, "{line}").map_err(|e| FileError::Io { path: path.clone(), source: e })?;
            rows.push(row);
            done += 1;
            progress(done, set.images.len());
        }
        metadata.flush().map_err(|e| FileError::Io { path, source: e })?;
    }
    staging.write("README.md", super::hf_card::card(&rows, &splits, &names).as_bytes())?;
    Ok(())
}
