//! `vkdiff eval`'s whole computation: both files read, COCOeval's twelve statistics, and the
//! figures the paper reports beside them (AR at IoU 0.5, F1 from AP and AR, instance mIoU and
//! foreground IoU), as named rows.

use crate::cocoeval::{evaluate, EvalParams, IouType};
use crate::dataset::{AreaRule, AreaSource, Dataset, Geometry};
use crate::masks::foreground_iou;
use crate::{EvalError, Result};
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::Path;
use vkdiff_setting::Message;

/// What to score and how.
pub struct SummaryRequest<'a> {
    pub gt: &'a Path,
    pub pred: &'a Path,
    pub iou_type: IouType,
    /// The detection caps per image, ascending (three for segm and bbox).
    pub max_dets: &'a [usize],
    /// Keypoint evaluation's sigmas, `None` for the default (`EvalParams::kpt_sigmas`).
    pub kpt_sigmas: Option<&'a [f64]>,
    /// Predictions at or above this score make the foreground mask.
    pub score_threshold: f64,
    pub area_rule: AreaRule,
}

/// The scores, with what they were computed over.
pub struct Summary {
    pub images: usize,
    pub gt_annotations: usize,
    pub predictions: usize,
    /// Where the detections' areas came from.
    pub areas: AreaSource,
    /// Each statistic by name, in the order they are printed.
    pub rows: Vec<(String, f64)>,
    /// Each category's scores, by id.
    pub per_category: Vec<CategoryScores>,
    /// Things the user should know about the files.
    pub warnings: Vec<String>,
    /// The sigmas keypoints were scored with (empty for segm and bbox).
    pub kpt_sigmas: Vec<f64>,
}

/// One category's AP (IoU 0.50:0.95), AP50 and AR, as pycocotools' per-category arrays give them.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CategoryScores {
    pub id: u64,
    pub name: String,
    pub ground_truth: usize,
    #[serde(rename = "AP")]
    pub ap: f64,
    #[serde(rename = "AP50")]
    pub ap50: f64,
    #[serde(rename = "AR")]
    pub ar: f64,
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

fn read_json(path: &Path) -> Result<Value> {
    let text = std::fs::read_to_string(path)
        .map_err(|source| EvalError::Io { what: Message::text(format!("cannot read {}", path.display())), source })?;
    serde_json::from_str(&text).map_err(|e| EvalError::Invalid(format!("{} is not JSON: {e}", path.display())))
}

/// `result`'s error prefixed by the file it came from.
fn in_file<T>(path: &Path, result: Result<T>) -> Result<T> {
    result.map_err(|e| e.context(path.display().to_string()))
}

/// Scores the predictions against the ground truth.
pub fn summarize(request: &SummaryRequest) -> Result<Summary> {
    let SummaryRequest { gt: gt_path, pred: pred_path, iou_type, max_dets, .. } = *request;
    let masks = iou_type == IouType::Segm;
    let gt = in_file(gt_path, Dataset::ground_truth(&read_json(gt_path)?, iou_type))?;
    let pred = read_json(pred_path)?;
    let areas = in_file(pred_path, AreaSource::of_results(&pred, request.area_rule))?;
    let dt = in_file(pred_path, Dataset::results(&pred, &gt, iou_type, areas))?;
    if gt.annotations.is_empty() {
        return Err(EvalError::Invalid(format!("{} holds no annotations", gt_path.display())));
    }
    let mut warnings = Vec::new();
    if gt.annotations.iter().any(|a| a.id == 0) {
        warnings.push(format!(
            "warning: {} has annotation id 0 (Roboflow exports start there); pycocotools counts \
            matches to it as false positives, vkdiff counts them as matches",
            gt_path.display()
        ));
    }
    let params =
        EvalParams { iou_type, max_dets: max_dets.to_vec(), kpt_sigmas: request.kpt_sigmas.map(<[f64]>::to_vec) };
    let stats = evaluate(&gt, &dt, &params)?;
    let v = &stats.values;
    let mut rows: Vec<(String, f64)> = stats.names.iter().cloned().zip(v.iter().copied()).collect();
    if iou_type == IouType::Keypoints {
        // _summarizeKps gives AR and AR at OKS 0.5 itself.
        rows.push(("F1".into(), f1(v[0], v[5])));
        rows.push(("F1_50".into(), f1(v[1], v[6])));
    } else {
        // Recall at IoU 0.5 over categories, at the last cap: AR's partner for AP50.
        let [_, _, k_n, a_n, m_n] = stats.dims;
        let r50: Vec<f64> = (0..k_n).map(|k| stats.recall[(k * a_n) * m_n + m_n - 1]).filter(|&r| r > -1.0).collect();
        let ar50 = if r50.is_empty() { -1.0 } else { r50.iter().sum::<f64>() / r50.len() as f64 };
        rows.push((format!("AR50@{}", max_dets[m_n - 1]), ar50));
        rows.push(("F1".into(), f1(v[0], v[8])));
        rows.push(("F1_50".into(), f1(v[1], ar50)));
    }
    if masks {
        rows.push(("mIoU".into(), stats.mean_instance_iou));
        rows.push(("mIoU_matched".into(), stats.mean_matched_iou));
        let mut per_image: BTreeMap<u64, (Vec<_>, Vec<_>)> = gt.images.keys().map(|&i| (i, (vec![], vec![]))).collect();
        for a in &gt.annotations {
            if let (Geometry::Mask(r), Some(e)) = (&a.geometry, per_image.get_mut(&a.image_id)) {
                e.0.push(r);
            }
        }
        for a in dt.annotations.iter().filter(|a| a.score >= request.score_threshold) {
            if let (Geometry::Mask(r), Some(e)) = (&a.geometry, per_image.get_mut(&a.image_id)) {
                e.1.push(r);
            }
        }
        rows.push(("foreground_IoU".into(), foreground_iou(&per_image.into_values().collect::<Vec<_>>())));
    }
    let per_category = stats
        .categories
        .iter()
        .enumerate()
        .map(|(k, &id)| {
            let [ap, ap50, ar] = stats.per_category(k);
            CategoryScores {
                id,
                name: gt.category_names.get(&id).cloned().unwrap_or_default(),
                ground_truth: gt.annotations.iter().filter(|a| a.category_id == id && !a.iscrowd).count(),
                ap,
                ap50,
                ar,
            }
        })
        .collect();
    Ok(Summary {
        images: gt.images.len(),
        gt_annotations: gt.annotations.len(),
        predictions: dt.annotations.len(),
        areas,
        rows,
        per_category,
        warnings,
        kpt_sigmas: stats.kpt_sigmas,
    })
}
