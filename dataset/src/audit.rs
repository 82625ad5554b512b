//! `vkdiff dataset audit DIR`: finds the images whose pixels no longer match their labels. With
//! a detector's or segmenter's predictions on the set's images (COCO results, as Detectron2 and
//! MMDetection write them, or Ultralytics' labels or JSON: audit_predictions.rs), each labelled object nothing detects is *missing*, each confident
//! detection mostly over unlabelled pixels *invented*, and each matched object whose predicted
//! mask overlaps its label poorly a *poor mask*; matches (by boxes unless asked for masks) are
//! the COCO evaluator's own (`vkdiff_eval::match_at`).
//! Without a model, every image and instance gets a boundary F-score of its edges against its
//! instance boundaries (audit_boundary.rs), beside the render's where the set keeps it. The
//! result is `DIR/audit.json`, with a summary by kind and category.

use crate::audit_boundary::{boundary_scores, strong_edges, BoundaryScore};
use crate::audit_predictions::{read_predictions, PredictionFormat, SetIndex};
use crate::audit_summary::summary;
use crate::error::{Error, Result};
use crate::export::{FinishedSet, SetImage, SplitFractions};
use serde_json::{json, Value};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use vkdiff_eval::{match_at, rle_iou, AreaRule, AreaSource, Dataset, Geometry, IouType};
use vkdiff_formats::atomic::write_atomic;
use vkdiff_formats::Error as FileError;
use vkdiff_pipeline::images::read_image;
use vkdiff_render::rle::Rle;
use vkdiff_setting::Message;

/// The audit file, in the set's folder.
pub const AUDIT: &str = "audit.json";

/// What the audit measures and where it draws its lines.
#[derive(Clone, Debug)]
pub struct AuditOptions {
    /// Predictions on the set's images; without them only boundary scores are computed.
    pub predictions: Option<PathBuf>,
    /// Their format; `None`: told by the file (audit_predictions.rs).
    pub format: Option<PredictionFormat>,
    /// Match by boxes (the default: a mask's quality is then judged apart) or masks.
    pub match_by: IouType,
    /// The IoU a detection must reach to match a labelled object.
    pub iou: f64,
    /// Predictions scoring below this are left out.
    pub min_score: f64,
    /// A matched object whose predicted mask's IoU with its label is below this is a poor mask.
    pub mask_iou: f64,
    /// Pixels between an edge and a boundary that still agree.
    pub tolerance: u32,
    /// The luminance gradient (0 to 1 per pixel) an edge must reach.
    pub edge_threshold: f64,
    /// An instance whose boundary F-score is below this share of the set's median instance
    /// score has a weak boundary (relative, since texture lowers every score of a photoreal set).
    pub min_boundary: f64,
}

impl Default for AuditOptions {
    fn default() -> AuditOptions {
        AuditOptions {
            predictions: None,
            format: None,
            match_by: IouType::Bbox,
            iou: 0.5,
            min_score: 0.5,
            mask_iou: 0.5,
            tolerance: 2,
            edge_threshold: 0.1,
            min_boundary: 0.85,
        }
    }
}

/// The kinds of flag, in the order they are reported.
pub const KINDS: [&str; 4] = ["missing", "invented", "poor_mask", "weak_boundary"];

/// What an audit wrote.
pub struct Audited {
    pub path: PathBuf,
    /// audit.json's `summary`.
    pub summary: Value,
}

fn setting(name: &str, why: &str) -> Error {
    Error::Setting(Message::setting(name).then(format!(" {why}")))
}

fn check(o: &AuditOptions) -> Result<()> {
    for (name, v) in [("iou", o.iou), ("mask-iou", o.mask_iou), ("min-boundary", o.min_boundary)] {
        if !(0.0..=1.0).contains(&v) {
            return Err(setting(name, &format!("is {v}: it takes a number from 0 to 1")));
        }
    }
    if !o.min_score.is_finite() {
        return Err(setting("min-score", "takes a number"));
    }
    if !(o.edge_threshold > 0.0 && o.edge_threshold.is_finite()) {
        return Err(setting("edge-threshold", "takes a positive number"));
    }
    if o.match_by == IouType::Keypoints {
        return Err(setting("match", "takes bbox or segm"));
    }
    Ok(())
}

/// The predictions, read and checked against the set before any image is looked at: those
/// scoring at least `min_score`, with their masks where they have them; and their format.
fn predictions(path: &Path, coco: &Value, gt: &Dataset, o: &AuditOptions) -> Result<(Dataset, PredictionFormat)> {
    let in_file = |e: vkdiff_eval::EvalError| Error::Eval(e.context(path.display().to_string()));
    let (json, format) = read_predictions(path, o.format, &SetIndex::of(coco))?;
    let list = json.as_array().map_or(&[][..], Vec::as_slice);
    let masks = list.first().is_some_and(|r| r.get("segmentation").is_some());
    if o.match_by == IouType::Segm && !masks && !list.is_empty() {
        return Err(Error::Config(format!(
            "{}: --match segm needs masks, and the results have no `segmentation` (match by bbox)",
            path.display()
        )));
    }
    let kept = Value::from(
        list.iter().filter(|r| r["score"].as_f64().is_none_or(|s| s >= o.min_score)).cloned().collect::<Vec<_>>(),
    );
    let read_as = if masks { IouType::Segm } else { IouType::Bbox };
    let areas = AreaSource::of_results(&kept, AreaRule::LoadRes).map_err(in_file)?;
    Ok((Dataset::results(&kept, gt, read_as, areas).map_err(in_file)?, format))
}

/// The share of a detection's pixels (its mask's, else its box's) that some label covers.
fn on_labels(d: &vkdiff_eval::Annotation, labelled: &[bool], width: usize) -> f64 {
    let pixels: Vec<usize> = match &d.geometry {
        Geometry::Mask(r) => r.to_mask().iter().enumerate().filter(|(_, on)| **on).map(|(p, _)| p).collect(),
        Geometry::Box => {
            let height = labelled.len() / width;
            let span = |lo: f64, len: f64, n: usize| {
                (lo.max(0.0).round() as usize).min(n)..((lo + len).round().max(0.0) as usize).min(n)
            };
            let (xs, ys) = (span(d.bbox[0], d.bbox[2], width), span(d.bbox[1], d.bbox[3], height));
            ys.flat_map(|y| xs.clone().map(move |x| y * width + x)).collect()
        }
    };
    if pixels.is_empty() {
        return 0.0;
    }
    pixels.iter().filter(|&&p| labelled[p]).count() as f64 / pixels.len() as f64
}

/// One instance's findings.
#[derive(Default)]
struct InstanceAudit {
    flags: Vec<&'static str>,
    /// The matched detection's IoU (by the matching's measure), its mask IoU and score.
    matched: Option<(f64, Option<f64>, f64)>,
    boundary: Option<BoundaryScore>,
}

/// Scores a picture's boundaries against the image's instance masks.
fn boundaries_of(
    picture: &Path,
    masks: &[&Rle],
    o: &AuditOptions,
) -> Result<(Option<BoundaryScore>, Vec<Option<BoundaryScore>>)> {
    let image = read_image(picture)?;
    let (w, h) = (image.width, image.height);
    let mut ids = vec![0u32; w * h];
    for (k, rle) in masks.iter().enumerate() {
        if (rle.width as usize, rle.height as usize) != (w, h) {
            return Err(Error::Config(format!(
                "{}: {w}×{h}, its masks {}×{}",
                picture.display(),
                rle.width,
                rle.height
            )));
        }
        for (p, _) in rle.to_mask().iter().enumerate().filter(|(_, &on)| on) {
            ids[p] = k as u32 + 1;
        }
    }
    let edges = strong_edges(&image.pixels, w, h, o.edge_threshold);
    Ok(boundary_scores(&edges, &ids, masks.len(), (w, h), o.tolerance))
}

/// The render an image was made from, where the set keeps it: the image itself for a
/// render-only set, else its init image.
fn render_of(image: &SetImage) -> Option<&str> {
    if image.entry["source"] == "render" {
        return Some(image.file_name());
    }
    image.entry["init_file"].as_str()
}

/// Flags `instances` (indexed as `gt`'s annotations) missing or with a poor mask by the
/// detections `dt`; returns the invented detections by image id.
fn flag_by_predictions(
    gt: &Dataset,
    dt: &Dataset,
    o: &AuditOptions,
    instances: &mut [InstanceAudit],
) -> HashMap<u64, Vec<Value>> {
    let by = o.match_by;
    let mut invented: HashMap<u64, Vec<Value>> = HashMap::new();
    let m = match_at(gt, dt, by, o.iou, usize::MAX);
    for pair in &m.matched {
        let (g, d) = (&gt.annotations[pair.gt], &dt.annotations[pair.dt]);
        let masks = match (&d.geometry, &g.geometry) {
            (Geometry::Mask(a), Geometry::Mask(b)) => Some(rle_iou(a, b)),
            _ => None,
        };
        let audit = &mut instances[pair.gt];
        audit.matched = Some((pair.iou, masks, d.score));
        if masks.is_some_and(|iou| iou < o.mask_iou) {
            audit.flags.push("poor_mask");
        }
    }
    for &g in &m.missed {
        instances[g].flags.push("missing");
    }
    // Unmatched detections mostly over pixels no label covers: objects the labels lack.
    let mut labelled: HashMap<u64, Vec<bool>> = HashMap::new();
    for &d in &m.unmatched {
        let d = &dt.annotations[d];
        let (h, w) = gt.images[&d.image_id];
        let labels = labelled.entry(d.image_id).or_insert_with(|| {
            let mut union = vec![false; (w * h) as usize];
            for g in gt.annotations.iter().filter(|g| g.image_id == d.image_id) {
                if let Geometry::Mask(r) = &g.geometry {
                    r.to_mask().iter().zip(union.iter_mut()).for_each(|(on, u)| *u |= on);
                }
            }
            union
        });
        if on_labels(d, labels, w as usize) < 0.5 {
            invented
                .entry(d.image_id)
                .or_default()
                .push(json!({"category_id": d.category_id, "bbox": d.bbox, "score": d.score}));
        }
    }
    invented
}

/// Audits the set in `dir`, writes `DIR/audit.json`; `progress(done, total)` per image.
pub fn audit(dir: &Path, o: &AuditOptions, progress: &mut dyn FnMut(usize, usize)) -> Result<Audited> {
    check(o)?;
    let set = FinishedSet::read(dir, &SplitFractions { val: 0.0, test: 0.0, seed: 0 })?;
    let coco_path = dir.join(crate::ANNOTATIONS);
    let coco: Value = serde_json::from_slice(
        &std::fs::read(&coco_path).map_err(|e| FileError::Io { path: coco_path.clone(), source: e })?,
    )
    .map_err(|e| FileError::Format { path: coco_path.clone(), why: e.to_string() })?;
    let gt = Dataset::ground_truth(&coco, IouType::Segm)
        .map_err(|e| Error::Eval(e.context(coco_path.display().to_string())))?;
    let read = o.predictions.as_deref().map(|p| predictions(p, &coco, &gt, o)).transpose()?;
    let (found, format) = read.map_or((None, None), |(dt, f)| (Some(dt), Some(f)));
    let by_id: HashMap<u64, usize> = gt.annotations.iter().enumerate().map(|(i, a)| (a.id, i)).collect();
    let mut instances: Vec<InstanceAudit> = (0..gt.annotations.len()).map(|_| InstanceAudit::default()).collect();
    let mut invented = match &found {
        Some(dt) => flag_by_predictions(&gt, dt, o, &mut instances),
        None => HashMap::new(),
    };
    // Every image's boundaries first: weak ones are judged against the set's own median.
    let mut scored = Vec::with_capacity(set.images.len());
    for (k, image) in set.images.iter().enumerate() {
        let own: Vec<usize> = image.annotations.iter().filter_map(|a| by_id.get(&a["id"].as_u64()?).copied()).collect();
        let masks: Vec<&Rle> = own
            .iter()
            .filter_map(|&i| match &gt.annotations[i].geometry {
                Geometry::Mask(r) => Some(r),
                Geometry::Box => None,
            })
            .collect();
        let (score, per_instance) = boundaries_of(&set.dir.join(image.file_name()), &masks, o)?;
        let render = match render_of(image) {
            Some(r) if r == image.file_name() => score,
            Some(r) => boundaries_of(&set.dir.join(r), &masks, o)?.0,
            None => None,
        };
        for (&i, b) in own.iter().zip(per_instance) {
            instances[i].boundary = b;
        }
        scored.push((own, score, render));
        progress(k + 1, set.images.len());
    }
    let mut fs: Vec<f64> = instances.iter().filter_map(|i| i.boundary.map(|b| b.f)).collect();
    fs.sort_by(f64::total_cmp);
    let median = fs.get(fs.len() / 2).copied();
    if let Some(median) = median {
        for i in instances.iter_mut().filter(|i| i.boundary.is_some_and(|b| b.f < o.min_boundary * median)) {
            i.flags.push("weak_boundary");
        }
    }
    let images: Vec<Value> = set
        .images
        .iter()
        .zip(scored)
        .map(|(image, (own, score, render))| {
            let id = image.entry["id"].as_u64().unwrap_or_default();
            let invented = invented.remove(&id).unwrap_or_default();
            image_record(image, id, &own, &gt, &instances, invented, score, render)
        })
        .collect();
    let flagged: Vec<(u64, &[&str])> =
        gt.annotations.iter().zip(&instances).map(|(a, i)| (a.category_id, &i.flags[..])).collect();
    let summary = summary(&images, &flagged, &coco["categories"]);
    let settings = json!({
        "predictions": o.predictions.as_ref().map(|p| p.display().to_string()),
        "predictions_format": format.map(PredictionFormat::name),
        "match": o.match_by.name(),
        "predictions_kept": found.as_ref().map(|dt| dt.annotations.len()),
        "iou": o.iou, "min_score": o.min_score, "mask_iou": o.mask_iou, "tolerance_px": o.tolerance,
        "edge_threshold": o.edge_threshold, "min_boundary": o.min_boundary, "median_instance_boundary_f": median,
    });
    let file = json!({"vkdiff": env!("CARGO_PKG_VERSION"), "settings": settings, "summary": summary, "images": images});
    let path = dir.join(AUDIT);
    write_atomic(&path, serde_json::to_string_pretty(&file).expect("JSON values serialise").as_bytes())?;
    Ok(Audited { path, summary })
}

/// DIR/audit.json, refused in one line where the set has not been audited (`to` says what the
/// audit was wanted for) or the file is not JSON.
pub(crate) fn read_audit(dir: &Path, to: &str) -> Result<Value> {
    let path = dir.join(AUDIT);
    if !path.is_file() {
        return Err(Error::Config(format!(
            "{} has no {AUDIT} {to}: run `vkdiff dataset audit {}` first",
            dir.display(),
            dir.display()
        )));
    }
    let text = std::fs::read(&path).map_err(|e| FileError::Io { path: path.clone(), source: e })?;
    let audit: Value = serde_json::from_slice(&text)
        .map_err(|e| FileError::Format { path: path.clone(), why: format!("not JSON: {e}") })?;
    if !audit["images"].is_array() {
        return Err(FileError::Format { path, why: "no `images` list".into() }.into());
    }
    Ok(audit)
}

/// Instances listed per image beside the flagged ones: the lowest boundary scores.
const WORST: usize = 5;

#[allow(clippy::too_many_arguments)]
fn image_record(
    image: &SetImage,
    id: u64,
    own: &[usize],
    gt: &Dataset,
    instances: &[InstanceAudit],
    invented: Vec<Value>,
    score: Option<BoundaryScore>,
    render: Option<BoundaryScore>,
) -> Value {
    let mut flags: Vec<&str> = KINDS
        .into_iter()
        .filter(|k| (*k == "invented" && !invented.is_empty()) || own.iter().any(|&i| instances[i].flags.contains(k)))
        .collect();
    flags.dedup();
    let mut worst: Vec<usize> = own.to_vec();
    worst.sort_by(|&a, &b| {
        let f = |i: usize| instances[i].boundary.map_or(f64::INFINITY, |b| b.f);
        f(a).total_cmp(&f(b))
    });
    let listed: Vec<usize> = worst
        .iter()
        .enumerate()
        .filter(|(rank, &i)| *rank < WORST || !instances[i].flags.is_empty())
        .map(|(_, &i)| i)
        .collect();
    let instance = |i: usize| {
        let (a, audit) = (&gt.annotations[i], &instances[i]);
        json!({
            "id": a.id, "category_id": a.category_id, "flags": audit.flags,
            "match_iou": audit.matched.map(|m| m.0), "mask_iou": audit.matched.and_then(|m| m.1),
            "score": audit.matched.map(|m| m.2), "boundary": audit.boundary,
        })
    };
    json!({
        "id": id, "file_name": image.file_name(), "flags": flags,
        "boundary": score, "render_boundary": render,
        "instances": own.len(), "invented": invented,
        "worst": listed.into_iter().map(instance).collect::<Vec<_>>(),
    })
}
