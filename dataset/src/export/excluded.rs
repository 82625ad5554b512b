//! `dataset export --exclude-flagged[=KINDS]` and `--min-boundary-score S`: the images the
//! audit (DIR/audit.json) flagged, or whose boundary F-score is below S, left out of every
//! format, and the kept and dropped lists written beside the export (`excluded.json`).

use super::set::FinishedSet;
use crate::audit::{read_audit, AUDIT, KINDS};
use crate::error::{Error, Result};
use serde_json::{json, Value};
use std::collections::BTreeMap;

/// The exclusion file an export writes at its root.
pub const EXCLUDED: &str = "excluded.json";

/// Which images to leave out.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Exclusion {
    /// Flag kinds that exclude an image (an empty list: none; every kind is `KINDS`).
    pub kinds: Vec<String>,
    /// Images whose boundary F-score is below this are left out.
    pub min_boundary_score: Option<f64>,
}

impl Exclusion {
    pub fn is_empty(&self) -> bool {
        self.kinds.is_empty() && self.min_boundary_score.is_none()
    }

    /// Refuses kinds the audit does not have and a score outside 0 to 1.
    pub fn check(&self) -> Result<()> {
        if let Some(kind) = self.kinds.iter().find(|k| !KINDS.contains(&k.as_str())) {
            return Err(Error::Config(format!(
                "--exclude-flagged: no flag `{kind}` (the audit's: {})",
                KINDS.join(", ")
            )));
        }
        if let Some(s) = self.min_boundary_score.filter(|s| !(0.0..=1.0).contains(s)) {
            return Err(Error::Config(format!("--min-boundary-score {s}: it takes a number from 0 to 1")));
        }
        Ok(())
    }
}

/// Drops from `set` the images `rule` excludes, by DIR/audit.json, which must cover every image
/// of the set; returns what excluded.json holds.
pub fn exclude(set: &mut FinishedSet, rule: &Exclusion) -> Result<Value> {
    let audit = read_audit(&set.dir, "to exclude by")?;
    let stale = |why: String| Error::Config(format!("{}: {why}", set.dir.join(AUDIT).display()));
    let audited: BTreeMap<u64, &Value> =
        audit["images"].as_array().into_iter().flatten().filter_map(|i| Some((i["id"].as_u64()?, i))).collect();
    let id_of = |entry: &Value| entry["id"].as_u64().unwrap_or_default();
    if let Some(image) = set.images.iter().find(|i| !audited.contains_key(&id_of(&i.entry))) {
        return Err(stale(format!(
            "the audit has no image {} ({}): the set changed after it; run `vkdiff dataset audit` again",
            id_of(&image.entry),
            image.file_name()
        )));
    }
    let reasons = |entry: &Value| -> Vec<String> {
        let record = audited[&id_of(entry)];
        let mut why: Vec<String> = record["flags"]
            .as_array()
            .into_iter()
            .flatten()
            .filter_map(Value::as_str)
            .filter(|f| rule.kinds.iter().any(|k| k == f))
            .map(str::to_string)
            .collect();
        let score = record["boundary"]["f"].as_f64();
        if let (Some(min), Some(f)) = (rule.min_boundary_score, score) {
            if f < min {
                why.push(format!("boundary F {f:.3} < {min}"));
            }
        }
        why
    };
    let (mut kept, mut dropped) = (Vec::new(), Vec::new());
    set.images.retain(|image| {
        let why = reasons(&image.entry);
        let entry = json!({"id": id_of(&image.entry), "file_name": image.file_name()});
        if why.is_empty() {
            kept.push(entry);
            true
        } else {
            dropped.push(json!({"id": entry["id"], "file_name": entry["file_name"], "reasons": why}));
            false
        }
    });
    Ok(json!({
        "rule": {"exclude_flagged": rule.kinds, "min_boundary_score": rule.min_boundary_score},
        "audit_settings": audit["settings"],
        "kept": kept,
        "dropped": dropped,
    }))
}
