//! `COCOeval` for segm and bbox: per image and category, detections sorted by score are matched
//! greedily to ground truth at each IoU threshold; precision is interpolated at 101 recall
//! points; the twelve statistics average it over categories (and thresholds), as pycocotools
//! 2.0 does. One deliberate difference: a match to a ground-truth annotation with id 0 counts
//! (pycocotools stores matches by id and takes 0 for "none").

use crate::dataset::{Annotation, Dataset, Geometry};
use crate::masks::{bbox as mask_box, bbox_iou, mask_iou, ones};
use crate::{EvalError, Result};
use std::collections::HashMap;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IouType {
    Segm,
    Bbox,
}

#[derive(Clone, Debug)]
pub struct EvalParams {
    pub iou_type: IouType,
    /// Three detection caps, ascending (pycocotools: 1, 10, 100).
    pub max_dets: [usize; 3],
}

/// Area ranges and their names, as pycocotools sets them.
const AREAS: [(f64, f64, &str); 4] =
    [(0.0, 1e10, "all"), (0.0, 1024.0, "small"), (1024.0, 9216.0, "medium"), (9216.0, 1e10, "large")];

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
    /// Mean over ground-truth instances (not crowd, any area) of the IoU with the detection
    /// matched to them at IoU ≥ 0.5 within the last detection cap, 0 for those unmatched.
    pub mean_instance_iou: f64,
    /// The same over the matched instances only.
    pub mean_matched_iou: f64,
}

/// One image × category × area range: what `evaluateImg` returns.
struct ImageEval {
    scores: Vec<f64>,
    /// [threshold][detection]: matched.
    matched: Vec<Vec<bool>>,
    /// [threshold][detection]: ignored.
    ignored: Vec<Vec<bool>>,
    gt_ignored: Vec<bool>,
    /// At IoU 0.5, the IoU of each ground truth (in `gt_ignored`'s order) with its match.
    gt_match_iou: Vec<Option<f64>>,
}

/// Indices sorted by descending score, ties in input order (numpy's stable mergesort).
fn by_score(anns: &[&Annotation]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..anns.len()).collect();
    order.sort_by(|&a, &b| anns[b].score.partial_cmp(&anns[a].score).unwrap_or(std::cmp::Ordering::Equal));
    order
}

/// IoU of every detection with every ground truth, [detection][ground truth].
fn ious(dts: &[&Annotation], gts: &[&Annotation], iou_type: IouType) -> Vec<Vec<f64>> {
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
    let g_ignore: Vec<bool> = gts.iter().map(|g| g.iscrowd || outside(g.area)).collect();
    // Not ignored first, stable.
    let mut g_order: Vec<usize> = (0..gts.len()).collect();
    g_order.sort_by_key(|&i| g_ignore[i]);
    let d = dts.len().min(max_det);
    let mut matched = vec![vec![false; d]; thresholds.len()];
    let mut ignored = vec![vec![false; d]; thresholds.len()];
    let mut gt_match_iou = vec![None; gts.len()];
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
    })
}

/// One image's ground truth and detections of a category, and their IoUs.
type ImageMatches<'a> = (Vec<&'a Annotation>, Vec<&'a Annotation>, Vec<Vec<f64>>);

/// Runs `COCOeval.evaluate()`, `accumulate()` and `summarize()` on `dt` against `gt`.
pub fn evaluate(gt: &Dataset, dt: &Dataset, p: &EvalParams) -> Result<Stats> {
    if !(p.max_dets[0] <= p.max_dets[1] && p.max_dets[1] <= p.max_dets[2] && p.max_dets[0] > 0) {
        return Err(EvalError::Invalid(format!("max detections {:?} must be positive and ascending", p.max_dets)));
    }
    let thresholds = linspace(0.5, 0.95, 10);
    let rec_thrs = linspace(0.0, 1.0, 101);
    let mut images: Vec<u64> = gt.images.keys().copied().collect();
    images.sort_unstable();
    let mut cats = gt.categories.clone();
    if cats.is_empty() {
        cats = gt.annotations.iter().map(|a| a.category_id).collect();
    }
    cats.sort_unstable();
    cats.dedup();
    let group = |d: &Dataset| {
        let mut m: HashMap<(u64, u64), Vec<usize>> = HashMap::new();
        for (i, a) in d.annotations.iter().enumerate() {
            m.entry((a.image_id, a.category_id)).or_default().push(i);
        }
        m
    };
    let (g_map, d_map) = (group(gt), group(dt));
    let max_det = p.max_dets[2];
    let (t_n, r_n, k_n, a_n, m_n) = (thresholds.len(), rec_thrs.len(), cats.len(), AREAS.len(), 3);
    // evalImgs[k][a][i]
    let mut evals: Vec<Option<ImageEval>> = Vec::with_capacity(k_n * a_n * images.len());
    for &cat in &cats {
        let per_image: Vec<ImageMatches> = images
            .iter()
            .map(|&img| {
                let gts: Vec<&Annotation> =
                    g_map.get(&(img, cat)).map_or(vec![], |v| v.iter().map(|&i| &gt.annotations[i]).collect());
                let dts: Vec<&Annotation> =
                    d_map.get(&(img, cat)).map_or(vec![], |v| v.iter().map(|&i| &dt.annotations[i]).collect());
                let mut dts: Vec<&Annotation> = by_score(&dts).into_iter().map(|i| dts[i]).collect();
                dts.truncate(max_det);
                let iou = ious(&dts, &gts, p.iou_type);
                (dts, gts, iou)
            })
            .collect();
        for &(lo, hi, _) in &AREAS {
            for (dts, gts, iou) in &per_image {
                evals.push(evaluate_image(dts, gts, iou, (lo, hi), &thresholds, max_det));
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
            for (m, &cap) in p.max_dets.iter().enumerate() {
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
    let (names, values) = summarize(&precision, &recall, dims, p.max_dets);
    Ok(Stats { names, values, precision, recall, dims, categories: cats, mean_instance_iou, mean_matched_iou })
}

/// pycocotools' `summarize()`: means over the defined (> -1) entries.
fn summarize(
    precision: &[f64],
    recall: &[f64],
    [t_n, r_n, k_n, a_n, m_n]: [usize; 5],
    max_dets: [usize; 3],
) -> (Vec<String>, Vec<f64>) {
    let mean = |vals: Vec<f64>| {
        let v: Vec<f64> = vals.into_iter().filter(|&x| x > -1.0).collect();
        if v.is_empty() {
            -1.0
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        }
    };
    let ap = |t: Option<usize>, a: usize| {
        let ts: Vec<usize> = t.map_or((0..t_n).collect(), |t| vec![t]);
        mean(
            ts.iter()
                .flat_map(|&t| {
                    (0..r_n).flat_map(move |r| {
                        (0..k_n).map(move |k| precision[(((t * r_n + r) * k_n + k) * a_n + a) * m_n + 2])
                    })
                })
                .collect(),
        )
    };
    let ar = |a: usize, m: usize| {
        mean((0..t_n).flat_map(|t| (0..k_n).map(move |k| recall[((t * k_n + k) * a_n + a) * m_n + m])).collect())
    };
    let d = max_dets[2];
    let tag = |name: &str| if d == 100 { name.to_string() } else { format!("{name}@{d}") };
    let names = [
        tag("AP"),
        tag("AP50"),
        tag("AP75"),
        tag("APs"),
        tag("APm"),
        tag("APl"),
        format!("AR{}", max_dets[0]),
        format!("AR{}", max_dets[1]),
        format!("AR{d}"),
        tag("ARs"),
        tag("ARm"),
        tag("ARl"),
    ];
    let values = vec![
        ap(None, 0),
        ap(Some(0), 0),
        ap(Some(5), 0),
        ap(None, 1),
        ap(None, 2),
        ap(None, 3),
        ar(0, 0),
        ar(0, 1),
        ar(0, 2),
        ar(1, 2),
        ar(2, 2),
        ar(3, 2),
    ];
    (names.to_vec(), values)
}

impl Stats {
    /// Category `k`'s AP over IoU 0.50:0.95, AP at 0.50, and AR, all areas, the last detection
    /// cap: the means pycocotools' per-category `precision[:, :, k, 0, -1]` and
    /// `recall[:, k, 0, -1]` give (-1 where the category has no ground truth).
    pub fn per_category(&self, k: usize) -> [f64; 3] {
        let [t_n, r_n, k_n, a_n, m_n] = self.dims;
        let mean = |v: Vec<f64>| {
            let v: Vec<f64> = v.into_iter().filter(|&x| x > -1.0).collect();
            if v.is_empty() {
                -1.0
            } else {
                v.iter().sum::<f64>() / v.len() as f64
            }
        };
        let precision = |ts: std::ops::Range<usize>| {
            mean(
                ts.flat_map(|t| (0..r_n).map(move |r| (t, r)))
                    .map(|(t, r)| self.precision[(((t * r_n + r) * k_n + k) * a_n) * m_n + m_n - 1])
                    .collect(),
            )
        };
        let recall = mean((0..t_n).map(|t| self.recall[((t * k_n + k) * a_n) * m_n + m_n - 1]).collect());
        [precision(0..t_n), precision(0..1), recall]
    }
}
