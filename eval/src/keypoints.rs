//! Keypoint evaluation's parts: COCO keypoints read as pycocotools reads them, the per-keypoint
//! falloffs (sigmas) and object keypoint similarity (`COCOeval.computeOks`).

use crate::dataset::{err, field, number, Annotation, Dataset};
use crate::Result;
use serde_json::Value;

/// COCO's person keypoints' sigmas (pycocotools' `kpt_oks_sigmas`), for 17 keypoints, divided
/// by ten as pycocotools divides them (0.35 / 10 is not 0.035 in binary).
pub const COCO_PERSON_SIGMAS: [f64; 17] = {
    let tenfold =
        [0.26, 0.25, 0.25, 0.35, 0.35, 0.79, 0.79, 0.72, 0.72, 0.62, 0.62, 1.07, 1.07, 0.87, 0.87, 0.89, 0.89];
    let mut sigmas = [0.0; 17];
    let mut i = 0;
    while i < 17 {
        sigmas[i] = tenfold[i] / 10.0;
        i += 1;
    }
    sigmas
};

/// An annotation's `keypoints` as numbers, x, y, v triples.
fn triples(v: &Value, what: &str) -> Result<Vec<f64>> {
    let list = v.as_array().ok_or_else(|| err(format!("{what}: `keypoints` is not a list of numbers")))?;
    if list.len() % 3 != 0 {
        return Err(err(format!("{what}: `keypoints` holds {} numbers, not x, y, v triples", list.len())));
    }
    list.iter().map(|x| number(x, what)).collect()
}

/// A ground-truth annotation's keypoints (empty where it has none) and its labelled count:
/// `num_keypoints` where given (what COCOeval reads), else the keypoints with v > 0.
pub fn ground_truth(a: &Value, what: &str) -> Result<(Vec<f64>, usize)> {
    let keypoints = a.get("keypoints").map_or(Ok(Vec::new()), |k| triples(k, what))?;
    let labelled = match a.get("num_keypoints") {
        Some(n) => n.as_u64().ok_or_else(|| err(format!("{what}: `num_keypoints` is not a count")))? as usize,
        None => keypoints.chunks(3).filter(|p| p[2] > 0.0).count(),
    };
    if labelled > 0 && keypoints.is_empty() {
        return Err(err(format!("{what}: `num_keypoints` is {labelled} but it has no `keypoints`")));
    }
    Ok((keypoints, labelled))
}

/// A result's keypoints, which keypoint evaluation needs.
pub fn result(a: &Value, what: &str) -> Result<Vec<f64>> {
    let keypoints = triples(field(a, "keypoints", what)?, what)?;
    if keypoints.is_empty() {
        return Err(err(format!("{what}: `keypoints` is empty")));
    }
    Ok(keypoints)
}

/// The area and box of the keypoints' extent, every keypoint counted (loadRes's rule).
pub fn extent(keypoints: &[f64]) -> (f64, [f64; 4]) {
    let axis = |first: usize| {
        let v = keypoints.iter().skip(first).step_by(3);
        (v.clone().copied().fold(f64::INFINITY, f64::min), v.copied().fold(f64::NEG_INFINITY, f64::max))
    };
    let ((x0, x1), (y0, y1)) = (axis(0), axis(1));
    ((x1 - x0) * (y1 - y0), [x0, y0, x1 - x0, y1 - y0])
}

/// The sigmas to score with: `given`, else COCO's person sigmas for 17 keypoints, else 1/k each
/// (Ultralytics' rule for other skeletons). Every keypoint list must hold that many; a ground
/// truth without keypoints counts as all unlabelled.
pub fn sigmas(given: Option<&[f64]>, gt: &Dataset, dt: &Dataset) -> Result<Vec<f64>> {
    let counted = |d: &Dataset| d.annotations.iter().find(|a| !a.keypoints.is_empty()).map(|a| a.keypoints.len() / 3);
    let k = match given {
        Some(s) => s.len(),
        None => counted(gt).or_else(|| counted(dt)).ok_or_else(|| err("no annotation has keypoints".into()))?,
    };
    let sigmas = match given {
        Some(s) => s.to_vec(),
        None if k == COCO_PERSON_SIGMAS.len() => COCO_PERSON_SIGMAS.to_vec(),
        None => vec![1.0 / k as f64; k],
    };
    if let Some(bad) = sigmas.iter().find(|s| !(s.is_finite() && **s > 0.0)) {
        return Err(err(format!("keypoint sigma {bad} is not a positive number")));
    }
    for (d, which) in [(gt, "ground truth"), (dt, "result")] {
        if let Some(a) = d.annotations.iter().find(|a| !a.keypoints.is_empty() && a.keypoints.len() != 3 * k) {
            return Err(err(format!(
                "{which} annotation {} has {} keypoints where {k} are scored (one sigma each{})",
                a.id,
                a.keypoints.len() / 3,
                if given.is_some() { ", --kpt-sigmas" } else { "" }
            )));
        }
    }
    Ok(sigmas)
}

/// Object keypoint similarity of a detection with a ground truth (`computeOks`): the mean of
/// exp(-d²/(2·s·(2σ)²)) over the ground truth's labelled keypoints, s its area; where it has
/// none, d is the detection's distance outside the ground truth's box grown by its size.
pub fn oks(d: &Annotation, g: &Annotation, sigmas: &[f64]) -> f64 {
    let k = sigmas.len();
    let unlabelled = vec![0.0; 3 * k];
    let gk = if g.keypoints.is_empty() { &unlabelled } else { &g.keypoints };
    let labelled = gk.chunks(3).filter(|p| p[2] > 0.0).count();
    let [bx, by, bw, bh] = g.bbox;
    let (x0, x1, y0, y1) = (bx - bw, bx + bw * 2.0, by - bh, by + bh * 2.0);
    let (mut sum, mut n) = (0.0, 0usize);
    for ((p, q), sigma) in d.keypoints.chunks(3).zip(gk.chunks(3)).zip(sigmas) {
        let (dx, dy) = if labelled > 0 {
            if q[2] <= 0.0 {
                continue;
            }
            (p[0] - q[0], p[1] - q[1])
        } else {
            ((x0 - p[0]).max(0.0) + (p[0] - x1).max(0.0), (y0 - p[1]).max(0.0) + (p[1] - y1).max(0.0))
        };
        let var = (sigma * 2.0) * (sigma * 2.0);
        let e = (dx * dx + dy * dy) / var / (g.area + f64::EPSILON) / 2.0;
        sum += (-e).exp();
        n += 1;
    }
    sum / n as f64
}
