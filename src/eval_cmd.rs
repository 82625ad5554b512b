//! `vkdiff eval`: COCO results scored against COCO ground truth as pycocotools' COCOeval does,
//! plus F1, instance mIoU and foreground IoU.

use anyhow::Result;
use serde_json::Value;
use std::path::PathBuf;
use vkdiff_eval::{summarize, AreaRule, AreaSource, IouType, SummaryRequest};

#[derive(clap::Args)]
pub struct EvalArgs {
    /// Ground truth, COCO JSON (segmentations as polygons, RLE or compressed RLE).
    #[arg(long)]
    gt: PathBuf,
    /// Predictions, COCO results JSON: a list of {image_id, category_id, segmentation or bbox, score}.
    #[arg(long)]
    pred: PathBuf,
    /// What is matched: masks (`segm`) or boxes (`bbox`).
    #[arg(long, default_value = "segm", value_parser = ["segm", "bbox"])]
    iou_type: String,
    /// The three detection caps per image, ascending. COCO's 100 caps recall on dense images
    /// (the paper's beds hold ~145 mushrooms each): raise the last, e.g. `--max-dets 1,10,300`.
    #[arg(long, default_value = "1,10,100", value_delimiter = ',')]
    max_dets: Vec<usize>,
    /// Predictions at or above this score make the foreground mask (foreground IoU, segm only).
    #[arg(long, default_value_t = 0.5)]
    score_threshold: f64,
    /// Where each detection's area, which sorts it into small / medium / large, comes from.
    /// `loadres`: as pycocotools' loadRes decides from the first result: w·h of the boxes when it
    /// has a bbox (what Detectron2, MMDetection and YOLO exporters write), else the masks.
    /// `mask`: the masks' areas whatever boxes the results carry (Detectron2's COCOEvaluator,
    /// which drops bbox before segm evaluation).
    #[arg(long, value_enum, default_value = "loadres")]
    area_from: AreaFromArg,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum AreaFromArg {
    Loadres,
    Mask,
}

pub fn run(args: &EvalArgs) -> Result<()> {
    let iou_type = if args.iou_type == "bbox" { IouType::Bbox } else { IouType::Segm };
    let max_dets: [usize; 3] =
        args.max_dets.clone().try_into().map_err(|_| vkdiff_args::Usage("--max-dets takes three numbers".into()))?;
    let rule = match args.area_from {
        AreaFromArg::Loadres => AreaRule::LoadRes,
        AreaFromArg::Mask => AreaRule::Mask,
    };
    let summary = summarize(&SummaryRequest {
        gt: &args.gt,
        pred: &args.pred,
        iou_type,
        max_dets,
        score_threshold: args.score_threshold,
        area_rule: rule,
    })?;
    for warning in &summary.warnings {
        eprintln!("{warning}");
    }
    let areas = summary.areas;
    let rule_name = match rule {
        AreaRule::LoadRes => "loadres",
        AreaRule::Mask => "mask",
    };
    if args.json {
        let mut map: serde_json::Map<String, Value> =
            summary.rows.iter().map(|(k, x)| (k.clone(), serde_json::json!(x))).collect();
        map.insert("area_from".into(), areas.name().into());
        map.insert("area_rule".into(), rule_name.into());
        map.insert("per_category".into(), serde_json::to_value(&summary.per_category)?);
        println!("{}", serde_json::to_string_pretty(&Value::Object(map))?);
        return Ok(());
    }
    println!(
        "{} images, {} ground-truth annotations, {} predictions, iou type {}",
        summary.images, summary.gt_annotations, summary.predictions, args.iou_type
    );
    let why = match (rule, areas) {
        (AreaRule::Mask, _) => "--area-from mask",
        (_, AreaSource::Box) => {
            "as pycocotools' loadRes: the first result has a bbox; --area-from mask for Detectron2's rule"
        }
        (_, AreaSource::Mask) => "as pycocotools' loadRes: the first result has no bbox",
    };
    println!("detection areas from each {} ({why})", areas.name());
    for (name, x) in &summary.rows {
        println!("{name:<16} {x:.4}");
    }
    if summary.per_category.len() > 1 {
        println!("per category (all areas, the last detection cap):");
        for c in &summary.per_category {
            println!(
                "  {:>4} {:<20} AP {:.4}  AP50 {:.4}  AR {:.4}  ({} ground truth)",
                c.id, c.name, c.ap, c.ap50, c.ar, c.ground_truth
            );
        }
    }
    Ok(())
}
