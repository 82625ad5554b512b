//! pycocotools' `summarize()`: COCOeval's statistics as means over its precision and recall
//! arrays, and each category's share of them.

use super::Stats;

/// Means over the defined (> -1) entries of the precision and recall arrays, as pycocotools'
/// `_summarize` takes them, at the last detection cap unless one is named.
struct Arrays<'a> {
    precision: &'a [f64],
    recall: &'a [f64],
    dims: [usize; 5],
}

impl Arrays<'_> {
    fn mean(vals: impl Iterator<Item = f64>) -> f64 {
        let (sum, n) = vals.filter(|&x| x > -1.0).fold((0.0, 0usize), |(sum, n), x| (sum + x, n + 1));
        if n == 0 {
            -1.0
        } else {
            sum / n as f64
        }
    }

    /// Thresholds `t` (all when `None`), area range `a`.
    fn thresholds(&self, t: Option<usize>) -> std::ops::Range<usize> {
        t.map_or(0..self.dims[0], |t| t..t + 1)
    }

    fn ap(&self, t: Option<usize>, a: usize) -> f64 {
        let [_, r_n, k_n, a_n, m_n] = self.dims;
        Self::mean(self.thresholds(t).flat_map(|t| {
            (0..r_n).flat_map(move |r| {
                (0..k_n).map(move |k| self.precision[(((t * r_n + r) * k_n + k) * a_n + a) * m_n + m_n - 1])
            })
        }))
    }

    fn ar(&self, t: Option<usize>, a: usize, m: usize) -> f64 {
        let [_, _, k_n, a_n, m_n] = self.dims;
        Self::mean(
            self.thresholds(t).flat_map(|t| (0..k_n).map(move |k| self.recall[((t * k_n + k) * a_n + a) * m_n + m])),
        )
    }
}

/// `name`, tagged with the last cap where it is not pycocotools' (`default`).
fn tagged(name: &str, cap: usize, default: usize) -> String {
    if cap == default {
        name.to_string()
    } else {
        format!("{name}@{cap}")
    }
}

/// pycocotools' `summarize()` for segm and bbox: the twelve statistics.
pub(super) fn summarize(
    precision: &[f64],
    recall: &[f64],
    dims: [usize; 5],
    max_dets: [usize; 3],
) -> (Vec<String>, Vec<f64>) {
    let s = Arrays { precision, recall, dims };
    let d = max_dets[2];
    let tag = |name: &str| tagged(name, d, 100);
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
        s.ap(None, 0),
        s.ap(Some(0), 0),
        s.ap(Some(5), 0),
        s.ap(None, 1),
        s.ap(None, 2),
        s.ap(None, 3),
        s.ar(None, 0, 0),
        s.ar(None, 0, 1),
        s.ar(None, 0, 2),
        s.ar(None, 1, 2),
        s.ar(None, 2, 2),
        s.ar(None, 3, 2),
    ];
    (names.to_vec(), values)
}

/// pycocotools' `_summarizeKps()`: AP and AR over OKS 0.50:0.95, at 0.50 and 0.75, and for
/// medium and large objects, at the last cap (pycocotools: 20).
pub(super) fn summarize_keypoints(
    precision: &[f64],
    recall: &[f64],
    dims: [usize; 5],
    cap: usize,
) -> (Vec<String>, Vec<f64>) {
    let s = Arrays { precision, recall, dims };
    let last = dims[4] - 1;
    let names = ["AP", "AP50", "AP75", "APm", "APl", "AR", "AR50", "AR75", "ARm", "ARl"];
    let values = vec![
        s.ap(None, 0),
        s.ap(Some(0), 0),
        s.ap(Some(5), 0),
        s.ap(None, 1),
        s.ap(None, 2),
        s.ar(None, 0, last),
        s.ar(Some(0), 0, last),
        s.ar(Some(5), 0, last),
        s.ar(None, 1, last),
        s.ar(None, 2, last),
    ];
    (names.iter().map(|n| tagged(n, cap, 20)).collect(), values)
}

impl Stats {
    /// Category `k`'s AP over IoU 0.50:0.95, AP at 0.50, and AR, all areas, the last detection
    /// cap: the means pycocotools' per-category `precision[:, :, k, 0, -1]` and
    /// `recall[:, k, 0, -1]` give (-1 where the category has no ground truth).
    pub fn per_category(&self, k: usize) -> [f64; 3] {
        let [t_n, r_n, k_n, a_n, m_n] = self.dims;
        let precision = |ts: std::ops::Range<usize>| {
            Arrays::mean(
                ts.flat_map(|t| (0..r_n).map(move |r| (t, r)))
                    .map(|(t, r)| self.precision[(((t * r_n + r) * k_n + k) * a_n) * m_n + m_n - 1]),
            )
        };
        let recall = Arrays::mean((0..t_n).map(|t| self.recall[((t * k_n + k) * a_n) * m_n + m_n - 1]));
        [precision(0..t_n), precision(0..1), recall]
    }
}
