//! `vkdiff dataset stats DIR`: what a finished set holds, and its charts.

use anyhow::Result;
use clap::Args;
use serde_json::Value;
use std::path::PathBuf;
use vkdiff_dataset::{stats, write_charts};

/// What a finished set holds, in figures and charts.
///
/// Images, instances per image, mask areas by COCO size class, instances cut by the image edge,
/// each category's instances, images and median area, the seeds, prompts and style sets used,
/// the choices each prompt template made at each of its positions; charts of instances per image, mask areas and instances by category as PNG.
#[derive(Args, Debug)]
pub struct StatsArgs {
    /// The dataset folder.
    dir: PathBuf,
    /// Print the statistics as JSON.
    #[arg(long)]
    json: bool,
    /// Where the charts go [default: DIR/stats].
    #[arg(long)]
    charts: Option<PathBuf>,
}

pub fn run(args: &StatsArgs) -> Result<()> {
    let mut stats = stats(&args.dir)?;
    let folder = args.charts.clone().unwrap_or_else(|| args.dir.join("stats"));
    let charts = write_charts(&stats, &folder)?;
    stats["charts"] = charts.iter().map(|p| p.display().to_string()).collect();
    if args.json {
        println!("{}", serde_json::to_string_pretty(&stats)?);
    } else {
        println!("{}", report(&stats));
    }
    Ok(())
}

fn report(s: &Value) -> String {
    let per = &s["instances_per_image"];
    let area = &s["mask_area_px"];
    let cut = &s["cut_by_image_edge"];
    let tally = |v: &Value| {
        let map = v.as_object().cloned().unwrap_or_default();
        let mut parts: Vec<String> = map.iter().take(5).map(|(k, n)| format!("{n}× {k:?}")).collect();
        if map.len() > 5 {
            parts.push(format!("… {} more", map.len() - 5));
        }
        if parts.is_empty() {
            "none".into()
        } else {
            parts.join(", ")
        }
    };
    let mut lines = vec![
        format!(
            "{}: {} images of {} scenes, {} instances",
            s["dataset"].as_str().unwrap_or_default(),
            s["images"],
            s["scenes"],
            s["instances"]
        ),
        format!(
            "instances per image: mean {:.1}, min {}, max {}",
            per["mean"].as_f64().unwrap_or(0.0),
            per["min"],
            per["max"]
        ),
        format!(
            "mask areas: {} small (< 32² px), {} medium (< 96² px), {} large (COCO's classes); median {} px",
            area["small"], area["medium"], area["large"], area["median"]
        ),
        format!(
            "cut by the image edge: {} instances ({:.1} %)",
            cut["instances"],
            100.0 * cut["share"].as_f64().unwrap_or(0.0)
        ),
        format!(
            "categories: {}",
            s["categories"]
                .as_array()
                .into_iter()
                .flatten()
                .map(|c| format!(
                    "{} {} instances in {} images (median {} px)",
                    c["name"].as_str().unwrap_or("?"),
                    c["instances"],
                    c["images"],
                    c["median_area_px"]
                ))
                .collect::<Vec<_>>()
                .join("; ")
        ),
        format!("image seeds: {} distinct; sources: {}", s["image_seeds"], tally(&s["sources"])),
        format!("prompts: {}", tally(&s["prompts"])),
    ];
    for (template, positions) in s["prompt_choices"].as_object().into_iter().flatten() {
        let images = &s["prompt_templates"][template];
        lines.push(format!("choices of template {template:?} ({images} images):"));
        for (at, counts) in positions.as_object().into_iter().flatten() {
            lines.push(format!("  {at}: {}", tally(counts)));
        }
    }
    let audit = &s["audit"];
    if audit.is_object() {
        let kinds: Vec<String> = audit["by_kind"]
            .as_object()
            .into_iter()
            .flatten()
            .map(|(kind, k)| format!("{kind} {}", k["images"]))
            .collect();
        let stale = if audit["covers_every_image"] == true { "" } else { " (older than the set: audit it again)" };
        lines.push(format!(
            "audit: images flagged {}, left out by export --exclude-flagged (images by kind: {}){stale}",
            audit["flagged"]["images"],
            kinds.join(", ")
        ));
    }
    lines.extend([
        format!("style sets: {}", tally(&s["style_sets"])),
        format!(
            "charts: {}",
            s["charts"].as_array().into_iter().flatten().filter_map(Value::as_str).collect::<Vec<_>>().join(", ")
        ),
    ]);
    lines.join("\n")
}
