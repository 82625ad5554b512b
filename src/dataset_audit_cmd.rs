//! `vkdiff dataset audit DIR`: the images whose pixels no longer match their labels.

use anyhow::Result;
use clap::Args;
use serde_json::Value;
use std::path::PathBuf;
use vkdiff_args::Progress;
use vkdiff_dataset::{audit, AuditOptions, PredictionFormat, AUDIT_KINDS};
use vkdiff_eval::IouType;

/// Finds the images whose pixels no longer match their labels, and writes DIR/audit.json.
///
/// With --predictions (COCO results of any detector or segmenter run on the set's images, as
/// Detectron2 and MMDetection write them), each labelled object nothing detects is flagged
/// missing, each confident detection mostly over unlabelled pixels invented, each object whose
/// predicted mask overlaps its label poorly a poor mask; matches are COCOeval's. Without a model, each image and
/// instance gets a boundary F-score of the image's strong edges against its instance
/// boundaries (and the render's, where the set keeps it); instances well below the set's median
/// (--min-boundary) are flagged weak_boundary.
#[derive(Args, Debug)]
pub struct AuditArgs {
    /// The dataset folder.
    dir: PathBuf,
    /// Predictions on the set's images: COCO results JSON (bbox or segm) with the set's image and
    /// category ids (Detectron2, MMDetection); Ultralytics' predict labels (a folder of STEM.txt
    /// written with save_txt=True, save_conf=True); or Ultralytics' JSON (val with
    /// save_json=True). Ultralytics names images by file stem and classes in the order of the
    /// set's categories, as `dataset export --format yolo` writes them.
    #[arg(long)]
    predictions: Option<PathBuf>,
    /// The predictions' format [default: told by the file: a folder is Ultralytics' labels, JSON
    /// naming images by file Ultralytics' JSON, else COCO results].
    #[arg(long, value_parser = ["coco", "ultralytics-txt", "ultralytics-json"])]
    predictions_format: Option<String>,
    /// Match detections to objects by boxes (a predicted mask is then judged by --mask-iou) or
    /// by masks.
    #[arg(long = "match", default_value = "bbox", value_parser = ["bbox", "segm"])]
    match_by: String,
    /// The IoU a detection must reach to match an object.
    #[arg(long, default_value_t = 0.5)]
    iou: f64,
    /// Predictions scoring below this are left out.
    #[arg(long, default_value_t = 0.5)]
    min_score: f64,
    /// A matched object whose predicted mask's IoU with its label is below this is a poor mask.
    #[arg(long, default_value_t = 0.5)]
    mask_iou: f64,
    /// Pixels between an image edge and a mask boundary that still agree.
    #[arg(long, default_value_t = 2)]
    tolerance: u32,
    /// The luminance step (0 to 1 per pixel, Sobel's) an image edge must reach.
    #[arg(long, default_value_t = 0.1)]
    edge_threshold: f64,
    /// Instances whose boundary F-score is below this share of the set's median instance score
    /// are flagged weak_boundary (relative: a photoreal image's texture lowers every score).
    #[arg(long, default_value_t = 0.85)]
    min_boundary: f64,
    /// Print the summary as JSON.
    #[arg(long)]
    json: bool,
}

pub fn run(args: &AuditArgs) -> Result<()> {
    let options = AuditOptions {
        predictions: args.predictions.clone(),
        format: args.predictions_format.as_deref().map(|f| match f {
            "ultralytics-txt" => PredictionFormat::UltralyticsTxt,
            "ultralytics-json" => PredictionFormat::UltralyticsJson,
            _ => PredictionFormat::Coco,
        }),
        match_by: if args.match_by == "bbox" { IouType::Bbox } else { IouType::Segm },
        iou: args.iou,
        min_score: args.min_score,
        mask_iou: args.mask_iou,
        tolerance: args.tolerance,
        edge_threshold: args.edge_threshold,
        min_boundary: args.min_boundary,
    };
    let bar = Progress::new("audit", "image");
    let audited = audit(&args.dir, &options, &mut |done, total| bar.update(done, total))?;
    let s = &audited.summary;
    if args.json {
        println!("{}", serde_json::to_string_pretty(s)?);
        return Ok(());
    }
    let percent = |v: &Value| format!("{:.1} %", 100.0 * v.as_f64().unwrap_or(0.0));
    println!("wrote {}", audited.path.display());
    println!("{} of {} images flagged ({})", s["flagged"]["images"], s["images"], percent(&s["flagged"]["share"]));
    for kind in AUDIT_KINDS {
        let k = &s["by_kind"][kind];
        let (what, count) =
            if kind == "invented" { ("detections", &k["detections"]) } else { ("instances", &k["instances"]) };
        println!("  {kind:<14} {:>6} images ({:>7}), {count} {what}", k["images"], percent(&k["share"]));
    }
    for c in s["by_category"].as_array().into_iter().flatten() {
        let shares: Vec<String> = AUDIT_KINDS
            .iter()
            .filter(|k| c["flags"][**k].is_object())
            .map(|k| format!("{k} {}", percent(&c["flags"][*k]["share"])))
            .collect();
        println!(
            "  category {} {} ({} instances): {}",
            c["id"],
            c["name"].as_str().unwrap_or(""),
            c["instances"],
            shares.join(", ")
        );
    }
    println!("boundary F-score of the images (the renders' beside them):");
    let (bins, renders) = (&s["boundary_f"]["bins"], &s["render_boundary_f"]["bins"]);
    let most = bins.as_array().into_iter().flatten().filter_map(|b| b["images"].as_u64()).max().unwrap_or(1).max(1);
    for (b, r) in bins.as_array().into_iter().flatten().zip(renders.as_array().into_iter().flatten()) {
        let n = b["images"].as_u64().unwrap_or(0);
        let bar = "█".repeat((n * 40).div_ceil(most) as usize);
        println!(
            "  {:.1}–{:.1} {n:>6} {bar:<40} (renders {})",
            b["from"].as_f64().unwrap_or(0.0),
            b["to"].as_f64().unwrap_or(0.0),
            r["images"]
        );
    }
    Ok(())
}
