//! `vkdiff eval`: COCO results scored against COCO ground truth as pycocotools' COCOeval does,
//! plus F1, instance mIoU and foreground IoU.

use anyhow::{bail, Context, Result};
use serde_json::Value;
use std::path::{Path, PathBuf};
use vkdiff_eval::{evaluate, foreground_iou, AreaRule, AreaSource, Dataset, EvalParams, Geometry, IouType};

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

fn read_json(path: &Path) -> Result<Value> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{} is not JSON", path.display()))
}

/// 2·a·b / (a + b), -1 where either is undefined.
fn f1(a: f64, b: f64) -> f64 {
    if a < 0.0 || b < 0.0 {
        -1.0
    } else if a + b == 0.0 {
        0.0
    } else {
        2.0 * a * b / (a + b)
    }
}

pub fn run(args: &EvalArgs) -> Result<()> {
    let iou_type = if args.iou_type == "bbox" { IouType::Bbox } else { IouType::Segm };
    let max_dets: [usize; 3] =
        args.max_dets.clone().try_into().map_err(|_| anyhow::anyhow!("--max-dets takes three numbers"))?;
    let masks = iou_type == IouType::Segm;
    let gt = Dataset::ground_truth(&read_json(&args.gt)?, masks).with_context(|| format!("{}", args.gt.display()))?;
    let pred = read_json(&args.pred)?;
    let rule = match args.area_from {
        AreaFromArg::Loadres => AreaRule::LoadRes,
        AreaFromArg::Mask => AreaRule::Mask,
    };
    let areas = AreaSource::of_results(&pred, rule).with_context(|| format!("{}", args.pred.display()))?;
    let dt = Dataset::results(&pred, &gt, masks, areas).with_context(|| format!("{}", args.pred.display()))?;
    if gt.annotations.is_empty() {
        bail!("{} holds no annotations", args.gt.display());
    }
    if gt.annotations.iter().any(|a| a.id == 0) {
        eprintln!("warning: {} has annotation id 0 (Roboflow exports start there); pycocotools counts matches to it as false positives, vkdiff counts them as matches", args.gt.display());
    }
    let stats = evaluate(&gt, &dt, &EvalParams { iou_type, max_dets })?;
    let v = &stats.values;
    // Recall at IoU 0.5 over categories, at the last cap: AR's partner for AP50.
    let [_, _, k_n, a_n, m_n] = stats.dims;
    let r50: Vec<f64> = (0..k_n).map(|k| stats.recall[(k * a_n) * m_n + 2]).filter(|&r| r > -1.0).collect();
    let ar50 = if r50.is_empty() { -1.0 } else { r50.iter().sum::<f64>() / r50.len() as f64 };
    let mut rows: Vec<(String, f64)> = stats.names.iter().cloned().zip(v.iter().copied()).collect();
    rows.push((format!("AR50@{}", max_dets[2]), ar50));
    rows.push(("F1".into(), f1(v[0], v[8])));
    rows.push(("F1_50".into(), f1(v[1], ar50)));
    if masks {
        rows.push(("mIoU".into(), stats.mean_instance_iou));
        rows.push(("mIoU_matched".into(), stats.mean_matched_iou));
        let mut per_image: std::collections::BTreeMap<u64, (Vec<_>, Vec<_>)> =
            gt.images.keys().map(|&i| (i, (vec![], vec![]))).collect();
        for a in &gt.annotations {
            if let (Geometry::Mask(r), Some(e)) = (&a.geometry, per_image.get_mut(&a.image_id)) {
                e.0.push(r);
            }
        }
        for a in dt.annotations.iter().filter(|a| a.score >= args.score_threshold) {
            if let (Geometry::Mask(r), Some(e)) = (&a.geometry, per_image.get_mut(&a.image_id)) {
                e.1.push(r);
            }
        }
        rows.push(("foreground_IoU".into(), foreground_iou(&per_image.into_values().collect::<Vec<_>>())));
    }
    let rule_name = match rule {
        AreaRule::LoadRes => "loadres",
        AreaRule::Mask => "mask",
    };
    if args.json {
        let mut map: serde_json::Map<String, Value> =
            rows.iter().map(|(k, x)| (k.clone(), serde_json::json!(x))).collect();
        map.insert("area_from".into(), areas.name().into());
        map.insert("area_rule".into(), rule_name.into());
        println!("{}", serde_json::to_string_pretty(&Value::Object(map))?);
        return Ok(());
    }
    println!(
        "{} images, {} ground-truth annotations, {} predictions, iou type {}",
        gt.images.len(),
        gt.annotations.len(),
        dt.annotations.len(),
        args.iou_type
    );
    let why = match (rule, areas) {
        (AreaRule::Mask, _) => "--area-from mask",
        (_, AreaSource::Box) => {
            "as pycocotools' loadRes: the first result has a bbox; --area-from mask for Detectron2's rule"
        }
        (_, AreaSource::Mask) => "as pycocotools' loadRes: the first result has no bbox",
    };
    println!("detection areas from each {} ({why})", areas.name());
    for (name, x) in rows {
        println!("{name:<16} {x:.4}");
    }
    Ok(())
}
