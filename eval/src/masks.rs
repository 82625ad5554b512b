//! COCO mask geometry on run-length encodings (column-major runs, zeros first): polygons
//! rasterised as pycocotools' `rleFrPoly` does, unions, areas, boxes and IoU.

use vkdiff_render::rle::Rle;

/// The runs of ones of an RLE as [start, end) flat (column-major) pixel ranges.
pub(crate) fn ones(r: &Rle) -> Vec<(u64, u64)> {
    let mut at = 0u64;
    let mut out = Vec::new();
    for (i, &c) in r.counts.iter().enumerate() {
        if i % 2 == 1 && c > 0 {
            out.push((at, at + c as u64));
        }
        at += c as u64;
    }
    out
}

fn from_ones(ranges: &[(u64, u64)], height: u32, width: u32) -> Rle {
    let mut counts = Vec::new();
    let mut at = 0u64;
    for &(s, e) in ranges {
        counts.push((s - at) as u32);
        counts.push((e - s) as u32);
        at = e;
    }
    counts.push((height as u64 * width as u64 - at) as u32);
    Rle { height, width, counts }
}

/// The union of masks of one size (pycocotools' `merge` without `intersect`).
pub fn union(rles: &[Rle], height: u32, width: u32) -> Rle {
    from_ones(&union_runs(rles.iter()), height, width)
}

/// The runs of ones of the union of `masks`, sorted and disjoint.
fn union_runs<'a>(masks: impl Iterator<Item = &'a Rle>) -> Vec<(u64, u64)> {
    let mut all: Vec<(u64, u64)> = masks.flat_map(ones).collect();
    all.sort_unstable();
    let mut merged: Vec<(u64, u64)> = Vec::new();
    for (s, e) in all {
        match merged.last_mut() {
            Some(last) if s <= last.1 => last.1 = last.1.max(e),
            _ => merged.push((s, e)),
        }
    }
    merged
}

/// Pixels in a mask's runs.
pub(crate) fn runs_area(runs: &[(u64, u64)]) -> u64 {
    runs.iter().map(|(s, e)| e - s).sum()
}

/// Pixels in both masks.
fn intersection(a: &[(u64, u64)], b: &[(u64, u64)]) -> u64 {
    let (mut i, mut j, mut n) = (0, 0, 0);
    while i < a.len() && j < b.len() {
        let (s, e) = (a[i].0.max(b[j].0), a[i].1.min(b[j].1));
        n += e.saturating_sub(s);
        if a[i].1 < b[j].1 {
            i += 1
        } else {
            j += 1
        }
    }
    n
}

/// IoU of a detection's mask with a ground-truth mask; against a crowd region, the part of the
/// detection inside it (intersection over the detection's area). 0 where the union is empty.
pub fn mask_iou(dt: &[(u64, u64)], gt: &[(u64, u64)], crowd: bool) -> f64 {
    let i = intersection(dt, gt);
    let u = if crowd { runs_area(dt) } else { runs_area(dt) + runs_area(gt) - i };
    if u == 0 {
        0.0
    } else {
        i as f64 / u as f64
    }
}

/// The IoU of two masks of one image (neither a crowd region).
pub fn rle_iou(a: &Rle, b: &Rle) -> f64 {
    mask_iou(&ones(a), &ones(b), false)
}

/// IoU of two `[x, y, w, h]` boxes, with the crowd rule of [`mask_iou`].
pub fn bbox_iou(dt: [f64; 4], gt: [f64; 4], crowd: bool) -> f64 {
    let w = (dt[0] + dt[2]).min(gt[0] + gt[2]) - dt[0].max(gt[0]);
    let h = (dt[1] + dt[3]).min(gt[1] + gt[3]) - dt[1].max(gt[1]);
    if w <= 0.0 || h <= 0.0 {
        return 0.0;
    }
    let i = w * h;
    let u = if crowd { dt[2] * dt[3] } else { dt[2] * dt[3] + gt[2] * gt[3] - i };
    i / u
}

/// The box `[x, y, w, h]` around a mask's pixels (`[0; 4]` when empty).
pub(crate) fn bbox(r: &Rle) -> [f64; 4] {
    let h = r.height as u64;
    let runs = ones(r);
    if runs.is_empty() {
        return [0.0; 4];
    }
    let (mut x0, mut y0, mut x1, mut y1) = (u64::MAX, u64::MAX, 0, 0);
    for (s, e) in runs {
        let (xs, xe) = (s / h, (e - 1) / h);
        let (ys, ye) = if xs == xe { (s % h, (e - 1) % h) } else { (0, h - 1) };
        (x0, x1, y0, y1) = (x0.min(xs), x1.max(xe), y0.min(ys), y1.max(ye));
    }
    [x0 as f64, y0 as f64, (x1 - x0 + 1) as f64, (y1 - y0 + 1) as f64]
}

/// A polygon `[x0, y0, x1, y1, …]` rasterised as pycocotools' `frPyObjects` does: vertices
/// scaled by 5 and rounded, the boundary walked pixel by pixel, and a pixel counted where its
/// centre lies inside by the crossings of each column.
pub fn polygon_rle(xy: &[f64], height: u32, width: u32) -> Rle {
    const SCALE: f64 = 5.0;
    let k = xy.len() / 2;
    let (h, w) = (height as i64, width as i64);
    if k == 0 {
        return from_ones(&[], height, width);
    }
    let mut x: Vec<i64> = (0..k).map(|j| (SCALE * xy[2 * j] + 0.5) as i64).collect();
    let mut y: Vec<i64> = (0..k).map(|j| (SCALE * xy[2 * j + 1] + 0.5) as i64).collect();
    x.push(x[0]);
    y.push(y[0]);
    // Every lattice point along the scaled boundary, each edge walked along its longer axis.
    let (mut u, mut v) = (Vec::new(), Vec::new());
    for j in 0..k {
        let (mut xs, mut xe, mut ys, mut ye) = (x[j], x[j + 1], y[j], y[j + 1]);
        let (dx, dy) = ((xe - xs).abs(), (ys - ye).abs());
        let flip = (dx >= dy && xs > xe) || (dx < dy && ys > ye);
        if flip {
            (xs, xe, ys, ye) = (xe, xs, ye, ys);
        }
        if dx >= dy {
            let s = if dx == 0 { 0.0 } else { (ye - ys) as f64 / dx as f64 };
            for d in 0..=dx {
                let t = if flip { dx - d } else { d };
                u.push(t + xs);
                v.push((ys as f64 + s * t as f64 + 0.5) as i64);
            }
        } else {
            let s = (xe - xs) as f64 / dy as f64;
            for d in 0..=dy {
                let t = if flip { dy - d } else { d };
                v.push(t + ys);
                u.push((xs as f64 + s * t as f64 + 0.5) as i64);
            }
        }
    }
    // Where the walk crosses a column centre: the first row below the boundary there.
    let mut starts: Vec<i64> = Vec::new();
    for j in 1..u.len() {
        if u[j] == u[j - 1] {
            continue;
        }
        let xd = ((if u[j] < u[j - 1] { u[j] } else { u[j] - 1 }) as f64 + 0.5) / SCALE - 0.5;
        if xd.floor() != xd || xd < 0.0 || xd > (w - 1) as f64 {
            continue;
        }
        let yd = ((v[j].min(v[j - 1])) as f64 + 0.5) / SCALE - 0.5;
        let yd = yd.clamp(0.0, h as f64).ceil();
        starts.push(xd as i64 * h + yd as i64);
    }
    // Sorted crossings alternate zeros and ones; equal neighbours cancel.
    starts.push(h * w);
    starts.sort_unstable();
    let mut gaps = Vec::with_capacity(starts.len());
    let mut prev = 0;
    for s in starts {
        gaps.push(s - prev);
        prev = s;
    }
    let mut counts: Vec<i64> = vec![gaps[0]];
    let mut j = 1;
    while j < gaps.len() {
        if gaps[j] > 0 {
            counts.push(gaps[j]);
            j += 1;
        } else {
            j += 1;
            if j < gaps.len() {
                *counts.last_mut().unwrap() += gaps[j];
                j += 1;
            }
        }
    }
    Rle { height, width, counts: counts.into_iter().map(|c| c as u32).collect() }
}

/// Foreground IoU over many images: Σ |G ∩ P| / Σ |G ∪ P|, where G is the union of an image's
/// ground-truth masks and P the union of its predicted masks (each a list of masks).
pub fn foreground_iou(images: &[(Vec<&Rle>, Vec<&Rle>)]) -> f64 {
    let (mut inter, mut uni) = (0u64, 0u64);
    for (gts, preds) in images {
        let (g, p) = (union_runs(gts.iter().copied()), union_runs(preds.iter().copied()));
        let i = intersection(&g, &p);
        inter += i;
        uni += runs_area(&g) + runs_area(&p) - i;
    }
    if uni == 0 {
        0.0
    } else {
        inter as f64 / uni as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 2×3 mask whose ones are the flat (column-major) pixels [start, end).
    fn run(start: u32, end: u32) -> Rle {
        Rle { height: 2, width: 3, counts: vec![start, end - start, 6 - end] }
    }

    #[test]
    fn foreground_iou_sums_intersections_and_unions_of_each_images_unions() {
        let (a1, a2, a3) = (run(0, 3), run(2, 4), run(3, 6));
        let (b, c) = (run(0, 2), run(1, 2));
        // Image 1: ground truth 0..4 (its two masks overlap at pixel 2), prediction 3..6: 1 of 6.
        // Image 2: a prediction only (0 of 2); image 3: ground truth only (0 of 1).
        let images = [(vec![&a1, &a2], vec![&a3]), (vec![], vec![&b]), (vec![&c], vec![])];
        assert_eq!(foreground_iou(&images), 1.0 / 9.0);
        // Masks that repeat one another change nothing.
        let doubled = [(vec![&a1, &a2, &a1], vec![&a3, &a3]), (vec![], vec![&b]), (vec![&c], vec![])];
        assert_eq!(foreground_iou(&doubled), 1.0 / 9.0);
        assert_eq!(foreground_iou(&[(vec![&a1], vec![&a1])]), 1.0);
        assert_eq!(foreground_iou(&[(vec![], vec![])]), 0.0);
    }

    #[test]
    fn a_run_down_a_column_into_the_next_spans_the_whole_height() {
        // 3×3, column-major: pixels (x 0, y 2) and (x 1, y 0), one run; a run that wraps a
        // column spans the image's full height, as pycocotools 2.0.11's toBbox gives both boxes.
        let r = Rle { height: 3, width: 3, counts: vec![2, 2, 5] };
        assert_eq!(bbox(&r), [0.0, 0.0, 2.0, 3.0]);
        assert_eq!(bbox(&run(1, 2)), [0.0, 1.0, 1.0, 1.0]);
    }

    /// Every ground-truth mask of the eval fixtures (polygons of one and two parts, RLE and
    /// compressed RLE) against the box and area pycocotools' `toBbox` and `area` gave for it.
    #[test]
    fn fixture_masks_have_pycocotools_boxes_and_areas() {
        let json: serde_json::Value = serde_json::from_str(include_str!("../../tests/fixtures/eval/gt.json")).unwrap();
        let written: std::collections::HashMap<u64, &serde_json::Value> =
            json["annotations"].as_array().unwrap().iter().map(|a| (a["id"].as_u64().unwrap(), a)).collect();
        let gt = crate::dataset::Dataset::ground_truth(&json, crate::IouType::Segm).unwrap();
        assert!(gt.annotations.len() > 20);
        for a in &gt.annotations {
            let crate::dataset::Geometry::Mask(r) = &a.geometry else { panic!("annotation {} has no mask", a.id) };
            let want = written[&a.id];
            let want_box: Vec<f64> = want["bbox"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
            assert_eq!(bbox(r).to_vec(), want_box, "annotation {}", a.id);
            assert_eq!(r.area() as f64, want["area"].as_f64().unwrap(), "annotation {}", a.id);
            let pixels: u64 = r.counts.iter().map(|&c| c as u64).sum();
            assert_eq!(pixels, r.height as u64 * r.width as u64, "annotation {}: runs past the image", a.id);
        }
    }
}
