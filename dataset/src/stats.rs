//! `vkdiff dataset stats`: what a finished set holds (images, instances per image, mask areas
//! by COCO size class, instances cut by the image edge, each category's instances, images and
//! median area, the seeds, prompts and style sets used, the choices prompt templates made, the
//! geometric labels), as
//! JSON and as the charts people look at first.

use super::canvas::bar_chart;
use super::export::{FinishedSet, SplitFractions};
use super::stats_geometry::geometry;
use crate::error::Result;
use serde_json::{json, Value};
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use vkdiff_formats::atomic::write_atomic;

/// COCO's size classes: small below 32², medium below 96², large above (areas in pixels).
const SMALL: u64 = 32 * 32;
const MEDIUM: u64 = 96 * 96;

/// The statistics of the finished set in `dir`, as JSON.
pub fn stats(dir: &Path) -> Result<Value> {
    let set = FinishedSet::read(dir, &SplitFractions { val: 0.0, test: 0.0, seed: 0 })?;
    let counts: Vec<u64> = set.images.iter().map(|i| i.annotations.len() as u64).collect();
    let areas: Vec<u64> = set.images.iter().flat_map(|i| &i.annotations).filter_map(|a| a["area"].as_u64()).collect();
    let mut cut = 0;
    for image in &set.images {
        let (w, h) = (image.entry["width"].as_u64().unwrap_or(0), image.entry["height"].as_u64().unwrap_or(0));
        for a in &image.annotations {
            let b: Vec<u64> = a["bbox"].as_array().into_iter().flatten().filter_map(Value::as_u64).collect();
            if b.len() == 4 && (b[0] == 0 || b[1] == 0 || b[0] + b[2] >= w || b[1] + b[3] >= h) {
                cut += 1;
            }
        }
    }
    let tally = |key: &str| -> BTreeMap<String, u64> {
        let mut counts = BTreeMap::new();
        for image in &set.images {
            let value = &image.entry[key];
            let name = match value {
                Value::Null => continue,
                Value::String(s) => s.clone(),
                Value::Array(items) => {
                    items.iter().map(|v| v.as_str().unwrap_or_default()).collect::<Vec<_>>().join(",")
                }
                other => other.to_string(),
            };
            *counts.entry(name).or_default() += 1;
        }
        counts
    };
    let categories: Vec<Value> = set
        .categories
        .as_array()
        .into_iter()
        .flatten()
        .map(|c| {
            let of = |a: &&Value| a["category_id"] == c["id"];
            let mut areas: Vec<u64> = set
                .images
                .iter()
                .flat_map(|i| i.annotations.iter().filter(of))
                .filter_map(|a| a["area"].as_u64())
                .collect();
            let images = set.images.iter().filter(|i| i.annotations.iter().any(|a| of(&a))).count();
            areas.sort_unstable();
            json!({
                "id": c["id"],
                "name": c["name"],
                "instances": areas.len(),
                "images": images,
                "median_area_px": median(&areas),
            })
        })
        .collect();
    let seeds: BTreeSet<u64> = set.images.iter().filter_map(|i| i.entry["seed"].as_u64()).collect();
    let scenes: BTreeSet<u64> = set.images.iter().map(|i| i.scene_seed).collect();
    let instances = areas.len() as u64;
    Ok(json!({
        "dataset": dir.display().to_string(),
        "images": set.images.len(),
        "scenes": scenes.len(),
        "instances": instances,
        "instances_per_image": {
            "mean": instances as f64 / set.images.len().max(1) as f64,
            "min": counts.iter().min(),
            "max": counts.iter().max(),
            "histogram": histogram(&counts, false),
        },
        "mask_area_px": {
            "small": areas.iter().filter(|&&a| a < SMALL).count(),
            "medium": areas.iter().filter(|&&a| (SMALL..MEDIUM).contains(&a)).count(),
            "large": areas.iter().filter(|&&a| a >= MEDIUM).count(),
            "median": median(&areas),
            "histogram": histogram(&areas, true),
        },
        "cut_by_image_edge": { "instances": cut, "share": cut as f64 / instances.max(1) as f64 },
        "categories": categories,
        "image_seeds": seeds.len(),
        "sources": tally("source"),
        "prompts": tally("prompt"),
        "prompt_templates": tally("prompt_template"),
        "prompt_choices": choices(&set),
        "style_sets": tally("ip_images"),
        "geometry": geometry(&set),
        "audit": audit_flags(&set)?,
    }))
}

/// What the set's audit (audit.json) flagged, by kind: the images `export --exclude-flagged`
/// leaves out; `null` for a set not audited.
fn audit_flags(set: &FinishedSet) -> Result<Value> {
    if !set.dir.join(crate::AUDIT).is_file() {
        return Ok(Value::Null);
    }
    let audit = crate::audit::read_audit(&set.dir, "")?;
    let audited: BTreeSet<u64> =
        audit["images"].as_array().into_iter().flatten().filter_map(|i| i["id"].as_u64()).collect();
    let current = set.images.iter().all(|i| i.entry["id"].as_u64().is_some_and(|id| audited.contains(&id)));
    Ok(json!({
        "flagged": audit["summary"]["flagged"],
        "by_kind": audit["summary"]["by_kind"],
        "covers_every_image": current,
    }))
}

/// Per template, per position in it (`at`), how many images took each alternative.
fn choices(set: &FinishedSet) -> BTreeMap<String, BTreeMap<String, BTreeMap<String, u64>>> {
    let mut counts: BTreeMap<String, BTreeMap<String, BTreeMap<String, u64>>> = BTreeMap::new();
    for image in &set.images {
        let Some(template) = image.entry["prompt_template"].as_str() else { continue };
        let positions = counts.entry(template.to_string()).or_default();
        for chosen in image.entry["prompt_choices"].as_array().into_iter().flatten() {
            let (at, choice) = (chosen["at"].as_str().unwrap_or("?"), chosen["choice"].as_str().unwrap_or("?"));
            *positions.entry(at.to_string()).or_default().entry(choice.to_string()).or_default() += 1;
        }
    }
    counts
}

fn median(values: &[u64]) -> Option<u64> {
    let mut sorted = values.to_vec();
    sorted.sort_unstable();
    sorted.get(sorted.len() / 2).copied()
}

/// Bins of `values`: one per value while they span at most 30, else 20 equal bins; powers of
/// two (`[2^k, 2^(k+1))`) when `log2`. Each bin is {from, to (exclusive), count}.
fn histogram(values: &[u64], log2: bool) -> Vec<Value> {
    let (Some(&min), Some(&max)) = (values.iter().min(), values.iter().max()) else { return Vec::new() };
    let edges: Vec<u64> = if log2 {
        let (first, last) = (63 - min.max(1).leading_zeros(), 64 - max.max(1).leading_zeros());
        (first..=last).map(|k| 1u64 << k).collect()
    } else if max - min <= 30 {
        (min..=max + 1).collect()
    } else {
        let step = (max - min + 1).div_ceil(20);
        (0..=20).map(|k| min + k * step).collect()
    };
    edges
        .windows(2)
        .map(|w| json!({"from": w[0], "to": w[1], "count": values.iter().filter(|&&v| v >= w[0] && v < w[1]).count()}))
        .collect()
}

/// Writes the charts of `stats` into `folder`: instances per image, mask areas and instances
/// by category. Returns their paths.
pub fn write_charts(stats: &Value, folder: &Path) -> Result<Vec<std::path::PathBuf>> {
    std::fs::create_dir_all(folder).map_err(|e| vkdiff_formats::Error::Io { path: folder.to_path_buf(), source: e })?;
    let bars = |histogram: &Value, label: &dyn Fn(u64, u64) -> String| -> Vec<(String, u64)> {
        let bins = histogram.as_array().into_iter().flatten();
        bins.map(|b| {
            let (from, to) = (b["from"].as_u64().unwrap_or(0), b["to"].as_u64().unwrap_or(0));
            (label(from, to), b["count"].as_u64().unwrap_or(0))
        })
        .collect()
    };
    let charts = [
        (
            "instances_per_image.png",
            bar_chart(
                &format!("INSTANCES PER IMAGE ({} IMAGES)", stats["images"]),
                "INSTANCES",
                &bars(&stats["instances_per_image"]["histogram"], &|from, to| {
                    if to == from + 1 {
                        from.to_string()
                    } else {
                        format!("{from}-{}", to - 1)
                    }
                }),
            ),
        ),
        (
            "mask_area.png",
            bar_chart(
                &format!("MASK AREA ({} INSTANCES)", stats["instances"]),
                "AREA IN PIXELS, FROM (POWERS OF 2)",
                &bars(&stats["mask_area_px"]["histogram"], &|from, _| short_number(from)),
            ),
        ),
        (
            "instances_by_category.png",
            bar_chart(
                &format!("INSTANCES BY CATEGORY ({} CATEGORIES)", stats["categories"].as_array().map_or(0, Vec::len)),
                "CATEGORY",
                &stats["categories"]
                    .as_array()
                    .into_iter()
                    .flatten()
                    .map(|c| (c["name"].as_str().unwrap_or("?").to_string(), c["instances"].as_u64().unwrap_or(0)))
                    .collect::<Vec<_>>(),
            ),
        ),
    ];
    let mut written = Vec::new();
    for (name, chart) in charts {
        let path = folder.join(name);
        write_atomic(&path, &chart.png())?;
        written.push(path);
    }
    Ok(written)
}

/// 1536 → 1.5K, 2097152 → 2M.
fn short_number(n: u64) -> String {
    match n {
        0..1000 => n.to_string(),
        1000..1_000_000 => format!("{}K", trim(n as f64 / 1e3)),
        _ => format!("{}M", trim(n as f64 / 1e6)),
    }
}

fn trim(v: f64) -> String {
    let text = format!("{v:.1}");
    text.trim_end_matches(".0").to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn histograms_bin_every_value_once() {
        let values = [1, 2, 2, 5, 40, 1000];
        for log2 in [false, true] {
            let bins = histogram(&values, log2);
            let total: u64 = bins.iter().map(|b| b["count"].as_u64().unwrap()).sum();
            assert_eq!(total, values.len() as u64, "{bins:?}");
        }
        let linear = histogram(&[3, 3, 4], false);
        assert_eq!(linear.len(), 2);
        assert_eq!((linear[0]["from"].as_u64(), linear[0]["count"].as_u64()), (Some(3), Some(2)));
        assert_eq!(histogram(&[1024], true)[0]["from"], 1024);
        assert_eq!(short_number(1536), "1.5K");
    }
}
