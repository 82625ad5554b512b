//! `COCOeval` for segm, bbox and keypoints: per image and category, detections sorted by score
//! are matched greedily to ground truth at each IoU (or OKS) threshold; precision is interpolated
//! at 101 recall points; the twelve statistics (ten for keypoints) average it over categories
//! (and thresholds), as pycocotools 2.0 does. One deliberate difference: a match to a ground-truth annotation with id 0 counts
//! (pycocotools stores matches by id and takes 0 for "none").

mod summarize;

use crate::dataset::{Annotation, Dataset, Geometry};
use crate::keypoints::{oks, sigmas};
use crate::masks::{bbox as mask_box, bbox_iou, mask_iou, ones};
use crate::{EvalError, Result};
use std::collections::HashMap;
use summarize::{summarize, summarize_keypoints};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IouType {
    Segm,
    Bbox,
    /// Object keypoint similarity (OKS) in place of IoU.
    Keypoints,
}

impl IouType {
    /// pycocotools' name (`iouType`).
    pub fn name(self) -> &'static str {
        match self {
            IouType::Segm => "segm",
            IouType::Bbox => "bbox",
            IouType::Keypoints => "keypoints",
        }
    }

    /// Area ranges and their names, as pycocotools sets them (keypoints have no small range).
    pub fn area_ranges(self) -> &'static [(f64, f64, &'static str)] {
        const OBJECTS: [(f64, f64, &str); 4] =
            [(0.0, 1e10, "all"), (0.0, 1024.0, "small"), (1024.0, 9216.0, "medium"), (9216.0, 1e10, "large")];
        const KEYPOINTS: [(f64, f64, &str); 3] =
            [(0.0, 1e10, "all"), (1024.0, 9216.0, "medium"), (9216.0, 1e10, "large")];
        match self {
            IouType::Keypoints => &KEYPOINTS,
            _ => &OBJECTS,
        }
    }

    /// pycocotools' detection caps: 1, 10, 100 (20 for keypoints).
    pub fn default_max_dets(self) -> Vec<usize> {
        match self {
            IouType::Keypoints => vec![20],
            _ => vec![1, 10, 100],
        }
    }
}

#[derive(Clone, Debug)]
pub struct EvalParams {
    pub iou_type: IouType,
    /// Detection caps, ascending: three for segm and bbox (pycocotools: 1, 10, 100), one or more
    /// for keypoints (20).
    pub max_dets: Vec<usize>,
    /// Keypoint evaluation's per-keypoint sigmas (`kpt_oks_sigmas`); `None` takes COCO's person
    /// sigmas for 17 keypoints, 1/k each for k others.
    pub kpt_sigmas: Option<Vec<f64>>,
}

/// numpy's `linspace(start, stop, n)`: i·step + start, the last value exactly `stop`.
fn linspace(start: f64, stop: f64, n: usize) -> Vec<f64> {
    let step = (stop - start) / (n - 1) as f64;
    (0..n).map(|i| if i == n - 1 { stop } else { i as f64 * step + start }).collect()
}

/// The twelve statistics, named, and the arrays they come from.
#[derive(Clone, Debug)]
pub struct Stats {
    pub names: Vec<String>,
    pub values: Vec<f64>,
    /// precision[t][r][k][a][m], -1 where undefined.
    pub precision: Vec<f64>,
    /// recall[t][k][a][m], -1 where undefined.
    pub recall: Vec<f64>,
    pub dims: [usize; 5],
    /// The category ids along the k axis, ascending (pycocotools' `catIds`).
    pub categories: Vec<u64>,
    /// The sigmas keypoints were scored with (empty for segm and bbox).
    pub kpt_sigmas: Vec<f64>,
    /// Mean over ground-truth instances (not crowd, any area) of the IoU with the detection
    /// matched to them at IoU ≥ 0.5 within the last detection cap, 0 for those unmatched.
    pub mean_instance_iou: f64,
    /// The same over the matched instances only.
    pub mean_matched_iou: f64,
}

/// One image × category × area range: what `evaluateImg` returns.
pub(crate) struct ImageEval {
    scores: Vec<f64>,
    /// [threshold][detection]: matched.
    matched: Vec<Vec<bool>>,
    /// [threshold][detection]: ignored.
    ignored: Vec<Vec<bool>>,
    gt_ignored: Vec<bool>,
    /// At IoU 0.5, the IoU of each ground truth (in `gt_ignored`'s order) with its match.
    gt_match_iou: Vec<Option<f64>>,
    /// At the first threshold, the ground truth (its index in the image's file order) each
    /// detection matched.
    pub(crate) dt_match: Vec<Option<usize>>,
}

/// Indices sorted by descending score, ties in input order (numpy's stable mergesort).
fn by_score(anns: &[&Annotation]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..anns.len()).collect();
    order.sort_by(|&a, &b| anns[b].score.partial_cmp(&anns[a].score).unwrap_or(std::cmp::Ordering::Equal));
    order
}

/// IoU (OKS for keypoints, scored with `sigmas`) of every detection with every ground truth,
/// [detection][ground truth].
fn ious(dts: &[&Annotation], gts: &[&Annotation], iou_type: IouType, sigmas: &[f64]) -> Vec<Vec<f64>> {
    // A mask's runs and the box around its pixels: masks whose boxes are apart share no pixel.
    let runs = |a: &Annotation| match &a.geometry {
        Geometry::Mask(r) => (ones(r), mask_box(r)),
        Geometry::Box => (Vec::new(), a.bbox),
    };
    let g_runs: Vec<_> = gts.iter().map(|g| runs(g)).collect();
    dts.iter()
        .map(|d| {
            let (d_runs, d_box) = runs(d);
            gts.iter()
                .zip(&g_runs)
                .map(|(g, (g_runs, g_box))| match iou_type {
                    IouType::Bbox => bbox_iou(d.bbox, g.bbox, g.iscrowd),
                    IouType::Keypoints => oks(d, g, sigmas),
                    IouType::Segm if !overlap(d_box, *g_box) => 0.0,
                    IouType::Segm => mask_iou(&d_runs, g_runs, g.iscrowd),
                })
                .collect()
        })
        .collect()
}

fn overlap(a: [f64; 4], b: [f64; 4]) -> bool {
    (a[0] + a[2]).min(b[0] + b[2]) > a[0].max(b[0]) && (a[1] + a[3]).min(b[1] + b[3]) > a[1].max(b[1])
}

/// `evaluateImg` for one image and category: detections (sorted, capped) and ground truth
/// (non-ignored first) and the IoU matrix in detection order × file order of ground truth.
fn evaluate_image(
    dts: &[&Annotation],
    gts: &[&Annotation],
    iou: &[Vec<f64>],
    area: (f64, f64),
    thresholds: &[f64],
    max_det: usize,
) -> Option<ImageEval> {
    if dts.is_empty() && gts.is_empty() {
        return None;
    }
    let outside = |x: f64| x < area.0 || x > area.1;
    let g_ignore: Vec<bool> = gts.iter().map(|g| g.ignore || outside(g.area)).collect();
    // Not ignored first, stable.
    let mut g_order: Vec<usize> = (0..gts.len()).collect();
    g_order.sort_by_key(|&i| g_ignore[i]);
    let d = dts.len().min(max_det);
    let mut matched = vec![vec![false; d]; thresholds.len()];
    let mut ignored = vec![vec![false; d]; thresholds.len()];
    let mut gt_match_iou = vec![None; gts.len()];
    let mut dt_match = vec![None; d];
    for (t, &thr) in thresholds.iter().enumerate() {
        let mut g_taken = vec![false; gts.len()];
        for di in 0..d {
            let mut best = thr.min(1.0 - 1e-10);
            let mut m: Option<usize> = None;
            for &gi in &g_order {
                if g_taken[gi] && !gts[gi].iscrowd {
                    continue;
                }
                if m.is_some_and(|m| !g_ignore[m]) && g_ignore[gi] {
                    break;
                }
                if iou[di][gi] < best {
                    continue;
                }
                best = iou[di][gi];
                m = Some(gi);
            }
            if let Some(gi) = m {
                matched[t][di] = true;
                ignored[t][di] = g_ignore[gi];
                g_taken[gi] = true;
                if t == 0 {
                    gt_match_iou[gi] = Some(iou[di][gi]);
                    dt_match[di] = Some(gi);
                }
            } else if outside(dts[di].area) {
                ignored[t][di] = true;
            }
        }
    }
    Some(ImageEval {
        scores: dts[..d].iter().map(|a| a.score).collect(),
        matched,
        ignored,
        gt_ignored: g_order.iter().map(|&i| g_ignore[i]).collect(),
        gt_match_iou: g_order.iter().map(|&i| gt_match_iou[i]).collect(),
        dt_match,
    })
}

/// One image's ground truth (file order) and detections (by score, capped) of a category, as
/// indices into their datasets' annotations, and their IoUs [detection][ground truth].
pub(crate) struct Pairing {
    pub(crate) gts: Vec<usize>,
    pub(crate) dts: Vec<usize>,
    pub(crate) iou: Vec<Vec<f64>>,
}

impl Pairing {
    /// `evaluateImg` of this pairing.
    pub(crate) fn evaluate(
        &self,
        gt: &Dataset,
        dt: &Dataset,
        area: (f64, f64),
        thresholds: &[f64],
        max_det: usize,
    ) -> Option<ImageEval> {
        let gts: Vec<&Annotation> = self.gts.iter().map(|&i| &gt.annotations[i]).collect();
        let dts: Vec<&Annotation> = self.dts.iter().map(|&i| &dt.annotations[i]).collect();
        evaluate_image(&dts, &gts, &self.iou, area, thresholds, max_det)
    }
}

/// Every image's pairing for category `cat`, `images` ascending.
pub(crate) fn pairings(
    gt: &Dataset,
    dt: &Dataset,
    cat: u64,
    images: &[u64],
    max_det: usize,
    iou_type: IouType,
    sigmas: &[f64],
) -> Vec<Pairing> {
    let group = |d: &Dataset| {
        let mut m: HashMap<u64, Vec<usize>> = HashMap::new();
        for (i, a) in d.annotations.iter().enumerate().filter(|(_, a)| a.category_id == cat) {
            m.entry(a.image_id).or_default().push(i);
        }
        m
    };
    let (g_map, d_map) = (group(gt), group(dt));
    images
        .iter()
        .map(|img| {
            let gts = g_map.get(img).cloned().unwrap_or_default();
            let found = d_map.get(img).cloned().unwrap_or_default();
            let refs: Vec<&Annotation> = found.iter().map(|&i| &dt.annotations[i]).collect();
            let mut dts: Vec<usize> = by_score(&refs).into_iter().map(|i| found[i]).collect();
            dts.truncate(max_det);
            let g: Vec<&Annotation> = gts.iter().map(|&i| &gt.annotations[i]).collect();
            let d: Vec<&Annotation> = dts.iter().map(|&i| &dt.annotations[i]).collect();
            let iou = ious(&d, &g, iou_type, sigmas);
            Pairing { gts, dts, iou }
        })
        .collect()
}

/// Runs `COCOeval.evaluate()`, `accumulate()` and `summarize()` on `dt` against `gt`.
pub fn evaluate(gt: &Dataset, dt: &Dataset, p: &EvalParams) -> Result<Stats> {
    let caps = &p.max_dets;
    let counted = if p.iou_type == IouType::Keypoints { !caps.is_empty() } else { caps.len() == 3 };
    if !counted || caps.windows(2).any(|w| w[0] > w[1]) || caps[0] == 0 {
        let needed = if p.iou_type == IouType::Keypoints { "one or more" } else { "three" };
        return Err(EvalError::Invalid(format!(
            "max detections {caps:?}: {} evaluation takes {needed}, positive and ascending",
            p.iou_type.name()
        )));
    }
    let areas = p.iou_type.area_ranges();
    let sigmas = match p.iou_type {
        IouType::Keypoints => sigmas(p.kpt_sigmas.as_deref(), gt, dt)?,
        _ => Vec::new(),
    };
    let thresholds = linspace(0.5, 0.95, 10);
    let rec_thrs = linspace(0.0, 1.0, 101);
    let (images, cats) = (gt.image_ids(), gt.category_ids());
    let max_det = caps[caps.len() - 1];
    let (t_n, r_n, k_n, a_n, m_n) = (thresholds.len(), rec_thrs.len(), cats.len(), areas.len(), caps.len());
    // evalImgs[k][a][i]
    let mut evals: Vec<Option<ImageEval>> = Vec::with_capacity(k_n * a_n * images.len());
    for &cat in &cats {
        let per_image = pairings(gt, dt, cat, &images, max_det, p.iou_type, &sigmas);
        for &(lo, hi, _) in areas {
            for pairing in &per_image {
                evals.push(pairing.evaluate(gt, dt, (lo, hi), &thresholds, max_det));
            }
        }
    }
    let mut precision = vec![-1.0; t_n * r_n * k_n * a_n * m_n];
    let mut recall = vec![-1.0; t_n * k_n * a_n * m_n];
    let n_img = images.len();
    for k in 0..k_n {
        for a in 0..a_n {
            let e: Vec<&ImageEval> = evals[(k * a_n + a) * n_img..][..n_img].iter().flatten().collect();
            if e.is_empty() {
                continue;
            }
            let npig = e.iter().flat_map(|e| &e.gt_ignored).filter(|&&i| !i).count();
            if npig == 0 {
                continue;
            }
            for (m, &cap) in caps.iter().enumerate() {
                // Every image's first `cap` detections, by score (stable across images).
                let mut dets: Vec<(f64, usize, usize)> = Vec::new();
                for (ei, e) in e.iter().enumerate() {
                    dets.extend(e.scores.iter().take(cap).enumerate().map(|(di, &s)| (s, ei, di)));
                }
                dets.sort_by(|x, y| y.0.partial_cmp(&x.0).unwrap_or(std::cmp::Ordering::Equal));
                for t in 0..t_n {
                    let (mut tp, mut fp) = (0.0f64, 0.0f64);
                    let mut rc = Vec::with_capacity(dets.len());
                    let mut pr = Vec::with_capacity(dets.len());
                    for &(_, ei, di) in &dets {
                        if e[ei].ignored[t][di] {
                        } else if e[ei].matched[t][di] {
                            tp += 1.0;
                        } else {
                            fp += 1.0;
                        }
                        rc.push(tp / npig as f64);
                        pr.push(tp / (fp + tp + f64::EPSILON));
                    }
                    recall[((t * k_n + k) * a_n + a) * m_n + m] = rc.last().copied().unwrap_or(0.0);
                    for i in (1..pr.len()).rev() {
                        if pr[i] > pr[i - 1] {
                            pr[i - 1] = pr[i];
                        }
                    }
                    // Precision at the first detection reaching each recall point; 0 past the last.
                    for (r, &thr) in rec_thrs.iter().enumerate() {
                        let at = rc.partition_point(|&x| x < thr);
                        precision[(((t * r_n + r) * k_n + k) * a_n + a) * m_n + m] = pr.get(at).copied().unwrap_or(0.0);
                    }
                }
            }
        }
    }
    // Instance IoUs from the "all" area range, whose evaluations are the first of each category.
    let all_area: Vec<Option<f64>> = (0..k_n)
        .flat_map(|k| evals[k * a_n * n_img..][..n_img].iter().flatten())
        .flat_map(|e| e.gt_ignored.iter().zip(&e.gt_match_iou).filter(|(ig, _)| !**ig).map(|(_, m)| *m))
        .collect();
    let matched: Vec<f64> = all_area.iter().flatten().copied().collect();
    let mean = |v: &[f64], n: usize| if n == 0 { -1.0 } else { v.iter().sum::<f64>() / n as f64 };
    let (mean_instance_iou, mean_matched_iou) = (mean(&matched, all_area.len()), mean(&matched, matched.len()));
    let dims = [t_n, r_n, k_n, a_n, m_n];
    let (names, values) = match p.iou_type {
        IouType::Keypoints => summarize_keypoints(&precision, &recall, dims, max_det),
        _ => summarize(&precision, &recall, dims, [caps[0], caps[1], caps[2]]),
    };
    let kpt_sigmas = sigmas;
    Ok(Stats {
        names,
        values,
        precision,
        recall,
        dims,
        categories: cats,
        kpt_sigmas,
        mean_instance_iou,
        mean_matched_iou,
    })
}
