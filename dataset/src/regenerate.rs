//! `vkdiff dataset --out DIR … --regenerate-flagged[=KINDS]`: the images the audit flagged made
//! again with new seeds, FreeMask's re-sampling step. Each flagged image's regeneration round is
//! recorded in DIR/resamples.json (its seed is then drawn from the first seed and the round, and
//! recorded in its entry with `resample`), its record is removed so that the run makes it again,
//! and annotations.json is removed until the run merges the set anew. Marking is tied to the
//! audit it read: the same command run again (after a stop) resumes, and bumps no round twice.

use crate::audit::{read_audit, KINDS};
use crate::error::{Error, Result};
use crate::folder::{fnv1a, Dataset, ANNOTATIONS};
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::path::Path;
use vkdiff_formats::atomic::write_atomic;
use vkdiff_formats::Error as FileError;

/// The regeneration rounds file, in the set's folder.
pub const RESAMPLES: &str = "resamples.json";

/// Each image's regeneration round (absent: 0), by index, as DIR/resamples.json records it.
pub fn read_rounds(dir: &Path) -> Result<BTreeMap<u64, u64>> {
    Ok(serde_json::from_value(read_resamples(dir)?["rounds"].clone()).unwrap_or_default())
}

fn read_resamples(dir: &Path) -> Result<Value> {
    let path = dir.join(RESAMPLES);
    match std::fs::read(&path) {
        Ok(text) => {
            let value: Value = serde_json::from_slice(&text)
                .map_err(|e| FileError::Format { path: path.clone(), why: format!("not JSON: {e}") })?;
            if !value["rounds"].is_object() {
                return Err(FileError::Format { path, why: "no `rounds` by image index".into() }.into());
            }
            Ok(value)
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(json!({"rounds": {}})),
        Err(e) => Err(FileError::Io { path, source: e }.into()),
    }
}

/// What marking did.
pub struct Marked {
    /// The images to make again.
    pub images: usize,
    /// Whether this audit's flags had been marked by an earlier run (a resume).
    pub resumed: bool,
}

/// Marks the images of `dataset` that DIR/audit.json flags with one of `kinds` (all where
/// empty) for regeneration; see the module's comment.
pub fn mark_flagged(dataset: &Dataset, kinds: &[String]) -> Result<Marked> {
    if let Some(kind) = kinds.iter().find(|k| !KINDS.contains(&k.as_str())) {
        return Err(Error::Config(format!(
            "--regenerate-flagged: no flag `{kind}` (the audit's: {})",
            KINDS.join(", ")
        )));
    }
    let dir = &dataset.dir;
    let audit = read_audit(dir, "to regenerate by")?;
    let audit_id = fnv1a(&audit.to_string());
    let mut resamples = read_resamples(dir)?;
    let resumed = resamples["audit"] == audit_id.as_str();
    if !resumed {
        let index_of: BTreeMap<String, u64> =
            (0..dataset.images).map(|i| (dataset.files(i).image.to_string(), i)).collect();
        let mut marked = Vec::new();
        for image in audit["images"].as_array().into_iter().flatten() {
            let flags = image["flags"].as_array().into_iter().flatten().filter_map(Value::as_str);
            if !flags.clone().any(|f| kinds.is_empty() || kinds.iter().any(|k| k == f)) {
                continue;
            }
            let name = image["file_name"].as_str().unwrap_or_default();
            let index = *index_of.get(name).ok_or_else(|| {
                Error::Config(format!("{}: image {name} is not one of the set's", dir.join(crate::AUDIT).display()))
            })?;
            let round = resamples["rounds"][index.to_string()].as_u64().unwrap_or(0) + 1;
            resamples["rounds"][index.to_string()] = round.into();
            marked.push(index);
        }
        resamples["audit"] = audit_id.into();
        resamples["marked"] = marked.into();
        // The rounds first: a stop before the records go leaves them to the next run.
        write_atomic(&dir.join(RESAMPLES), serde_json::to_string_pretty(&resamples).expect("JSON").as_bytes())?;
    }
    let rounds = read_rounds(dir)?;
    let marked: Vec<u64> = serde_json::from_value(resamples["marked"].clone()).unwrap_or_default();
    for &index in &marked {
        // A record of an earlier round is removed; one of this round is the image made again.
        let made = dataset.finished(index).ok().and_then(|r| r.image["resample"].as_u64()).unwrap_or(0);
        let record = dir.join(dataset.files(index).record);
        if made != rounds.get(&index).copied().unwrap_or(0) && record.is_file() {
            std::fs::remove_file(&record).map_err(|e| FileError::Io { path: record.clone(), source: e })?;
        }
    }
    let coco = dir.join(ANNOTATIONS);
    if !marked.is_empty() && coco.is_file() {
        std::fs::remove_file(&coco).map_err(|e| FileError::Io { path: coco.clone(), source: e })?;
    }
    Ok(Marked { images: marked.len(), resumed })
}
