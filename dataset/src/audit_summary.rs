//! audit.json's summary: the share of images flagged, by kind and by category, and histograms
//! of the images' boundary F-scores (the generated images' and the renders').

use crate::audit::KINDS;
use serde_json::{json, Value};
use std::collections::BTreeMap;

/// Histogram bins of a score from 0 to 1.
const BINS: usize = 10;

fn histogram(scores: impl Iterator<Item = f64>) -> Value {
    let mut counts = [0u64; BINS];
    let mut n = 0;
    for f in scores {
        counts[((f * BINS as f64) as usize).min(BINS - 1)] += 1;
        n += 1;
    }
    let bins: Vec<Value> = counts
        .iter()
        .enumerate()
        .map(|(i, c)| json!({"from": i as f64 / BINS as f64, "to": (i + 1) as f64 / BINS as f64, "images": c}))
        .collect();
    json!({"images": n, "bins": bins})
}

fn share(part: usize, whole: usize) -> f64 {
    if whole == 0 {
        0.0
    } else {
        part as f64 / whole as f64
    }
}

/// The summary of `images` (audit.json's records) and every instance's category and flags.
pub fn summary(images: &[Value], instances: &[(u64, &[&str])], categories: &Value) -> Value {
    let has = |image: &Value, kind: &str| image["flags"].as_array().is_some_and(|f| f.iter().any(|f| f == kind));
    let n = images.len();
    let flagged = images.iter().filter(|i| i["flags"].as_array().is_some_and(|f| !f.is_empty())).count();
    let mut by_kind = serde_json::Map::new();
    for kind in KINDS {
        let with = images.iter().filter(|i| has(i, kind)).count();
        // Invented detections belong to no labelled instance: counted as detections.
        let (what, count) = match kind {
            "invented" => ("detections", images.iter().map(|i| i["invented"].as_array().map_or(0, Vec::len)).sum()),
            _ => ("instances", instances.iter().filter(|(_, f)| f.contains(&kind)).count()),
        };
        by_kind.insert(kind.into(), json!({"images": with, "share": share(with, n), what: count}));
    }
    let names: BTreeMap<u64, &str> = categories
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|c| Some((c["id"].as_u64()?, c["name"].as_str().unwrap_or_default())))
        .collect();
    let mut per_category: BTreeMap<u64, (usize, BTreeMap<&str, usize>)> = BTreeMap::new();
    for (category, flags) in instances {
        let entry = per_category.entry(*category).or_default();
        entry.0 += 1;
        for kind in *flags {
            *entry.1.entry(kind).or_default() += 1;
        }
    }
    let by_category: Vec<Value> = per_category
        .into_iter()
        .map(|(id, (total, kinds))| {
            let kinds: serde_json::Map<String, Value> = KINDS
                .iter()
                .filter(|k| **k != "invented")
                .map(|k| {
                    let c = kinds.get(k).copied().unwrap_or(0);
                    (k.to_string(), json!({"instances": c, "share": share(c, total)}))
                })
                .collect();
            json!({"id": id, "name": names.get(&id).copied().unwrap_or_default(), "instances": total, "flags": kinds})
        })
        .collect();
    let scores = |key: &'static str| images.iter().filter_map(move |i| i[key]["f"].as_f64());
    json!({
        "images": n,
        "flagged": {"images": flagged, "share": share(flagged, n)},
        "by_kind": by_kind,
        "by_category": by_category,
        "boundary_f": histogram(scores("boundary")),
        "render_boundary_f": histogram(scores("render_boundary")),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shares_count_images_and_instances_by_kind_and_category() {
        let images = [
            json!({"flags": ["missing", "invented"], "invented": [{}, {}], "boundary": {"f": 0.95}}),
            json!({"flags": [], "invented": [], "boundary": {"f": 0.05}, "render_boundary": {"f": 1.0}}),
            json!({"flags": ["weak_boundary"], "invented": [], "boundary": {"f": 0.1}}),
            json!({"flags": [], "invented": []}),
        ];
        let instances: Vec<(u64, &[&str])> = vec![(1, &["missing"]), (1, &[]), (2, &["weak_boundary"]), (2, &[])];
        let s = summary(&images, &instances, &json!([{"id": 1, "name": "cap"}, {"id": 2, "name": "stem"}]));
        assert_eq!(s["flagged"], json!({"images": 2, "share": 0.5}));
        assert_eq!(s["by_kind"]["invented"], json!({"images": 1, "share": 0.25, "detections": 2}));
        assert_eq!(s["by_kind"]["missing"], json!({"images": 1, "share": 0.25, "instances": 1}));
        assert_eq!(s["by_category"][1]["flags"]["weak_boundary"], json!({"instances": 1, "share": 0.5}));
        assert_eq!(s["by_category"][0]["name"], "cap");
        let bins: Vec<u64> =
            s["boundary_f"]["bins"].as_array().unwrap().iter().map(|b| b["images"].as_u64().unwrap()).collect();
        assert_eq!(bins, [1, 1, 0, 0, 0, 0, 0, 0, 0, 1]);
        assert_eq!(s["render_boundary_f"]["images"], 1);
    }
}
