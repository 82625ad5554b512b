//! `vkdiff eval`: COCO results scored against COCO ground truth as pycocotools' COCOeval does
//! (masks, boxes or keypoints), plus F1, instance mIoU and foreground IoU.

use anyhow::Result;
use serde_json::Value;
use std::path::PathBuf;
use vkdiff_eval::{summarize, AreaRule, AreaSource, IouType, SummaryRequest};

#[derive(clap::Args)]
pub struct EvalArgs {
    /// Ground truth, COCO JSON (segmentations as polygons, RLE or compressed RLE).
    #[arg(long)]
    gt: PathBuf,
    /// Predictions, COCO results JSON: a list of {image_id, category_id, segmentation, bbox or
    /// keypoints, score}.
    #[arg(long)]
    pred: PathBuf,
    /// What is matched: masks (`segm`), boxes (`bbox`) or keypoints by object keypoint
    /// similarity (`keypoints`, COCO's keypoint challenge metric).
    #[arg(long, default_value = "segm", value_parser = ["segm", "bbox", "keypoints"])]
    iou_type: String,
    /// The detection caps per image, ascending: three for segm and bbox (default 1,10,100),
    /// any number for keypoints (default 20). COCO's 100 caps recall on dense images (the
    /// paper's beds hold ~145 mushrooms each): raise the last, e.g. `--max-dets 1,10,300`.
    #[arg(long, value_delimiter = ',')]
    max_dets: Option<Vec<usize>>,
    /// Keypoint evaluation's per-keypoint sigmas, one per keypoint, comma-separated (pycocotools'
    /// kpt_oks_sigmas). Default: COCO's person sigmas for 17 keypoints, 1/k each for k others
    /// (Ultralytics' rule); vkdiff's 3D-box keypoints are 9.
    #[arg(long, value_delimiter = ',')]
    kpt_sigmas: Option<Vec<f64>>,
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
    let iou_type = match args.iou_type.as_str() {
        "bbox" => IouType::Bbox,
        "keypoints" => IouType::Keypoints,
        _ => IouType::Segm,
    };
    let max_dets = args.max_dets.clone().unwrap_or_else(|| iou_type.default_max_dets());
    if iou_type != IouType::Keypoints && max_dets.len() != 3 {
        return Err(
            vkdiff_args::Usage(format!("--max-dets takes three numbers for --iou-type {}", args.iou_type)).into()
        );
    }
    if iou_type != IouType::Keypoints && args.kpt_sigmas.is_some() {
        return Err(vkdiff_args::Usage("--kpt-sigmas is for --iou-type keypoints".into()).into());
    }
    let rule = match args.area_from {
        AreaFromArg::Loadres => AreaRule::LoadRes,
        AreaFromArg::Mask if iou_type == IouType::Keypoints => return Err(vkdiff_args::Usage(
            "--area-from mask is Detectron2's rule for segm; keypoint results' areas are read as loadRes reads them"
                .into(),
        )
        .into()),
        AreaFromArg::Mask => AreaRule::Mask,
    };
    let summary = summarize(&SummaryRequest {
        gt: &args.gt,
        pred: &args.pred,
        iou_type,
        max_dets: &max_dets,
        kpt_sigmas: args.kpt_sigmas.as_deref(),
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
        if iou_type == IouType::Keypoints {
            map.insert("kpt_sigmas".into(), serde_json::to_value(&summary.kpt_sigmas)?);
        }
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
        (_, AreaSource::Keypoints) => "as pycocotools' loadRes: the first result has neither bbox nor segmentation",
    };
    println!("detection areas from each {} ({why})", areas.name());
    if iou_type == IouType::Keypoints {
        let sigmas: Vec<String> = summary.kpt_sigmas.iter().map(|s| format!("{s:.4}")).collect();
        println!("OKS sigmas ({} keypoints): {}", sigmas.len(), sigmas.join(", "));
    }
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
