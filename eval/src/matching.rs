//! Matches at one IoU threshold, as COCOeval's `evaluateImg` makes them (area "all"): what
//! `vkdiff dataset audit` flags images by, so that its matches are the evaluator's own.

use crate::cocoeval::{pairings, IouType};
use crate::dataset::Dataset;

/// A detection matched to a ground truth: indices into the datasets' annotations.
#[derive(Clone, Debug, PartialEq)]
pub struct Matched {
    pub gt: usize,
    pub dt: usize,
    pub iou: f64,
}

/// Every detection and ground truth, matched or not.
#[derive(Clone, Debug, Default)]
pub struct Matching {
    /// Matches, crowd regions' included (their ground truth has `ignore` set).
    pub matched: Vec<Matched>,
    /// Ground truth not ignored that no detection matched.
    pub missed: Vec<usize>,
    /// Detections (within the cap) that matched nothing.
    pub unmatched: Vec<usize>,
}

/// Matches `dt` to `gt` per image and category at IoU `threshold`, each image's detections of a
/// category taken by score up to `max_det`.
pub fn match_at(gt: &Dataset, dt: &Dataset, iou_type: IouType, threshold: f64, max_det: usize) -> Matching {
    let images = gt.image_ids();
    let mut out = Matching::default();
    for cat in gt.category_ids() {
        for pairing in pairings(gt, dt, cat, &images, max_det, iou_type, &[]) {
            let Some(e) = pairing.evaluate(gt, dt, (0.0, 1e10), &[threshold], max_det) else { continue };
            let mut taken = vec![false; pairing.gts.len()];
            for (d, m) in e.dt_match.iter().enumerate() {
                match *m {
                    Some(g) => {
                        taken[g] = true;
                        out.matched.push(Matched { gt: pairing.gts[g], dt: pairing.dts[d], iou: pairing.iou[d][g] });
                    }
                    None => out.unmatched.push(pairing.dts[d]),
                }
            }
            let missed = pairing.gts.iter().zip(taken).filter(|(&g, taken)| !taken && !gt.annotations[g].ignore);
            out.missed.extend(missed.map(|(&g, _)| g));
        }
    }
    out
}
