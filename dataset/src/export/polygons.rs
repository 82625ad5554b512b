//! Instance masks as the one polygon per instance that YOLO segmentation labels hold.
//!
//! The mask's boundary is traced along pixel edges (so the traced rings cover the mask exactly,
//! where contours through pixel centres, as OpenCV's, lose half a pixel all round), each ring is
//! simplified, and the rings of a multi-part or holed instance are joined into one by zero-width
//! bridges, as Ultralytics' COCO converter joins a multi-part instance's polygons. A bridge is
//! walked there and back, so it adds nothing to the filled area; a hole's ring runs the other
//! way round, so it stays a hole under both fill rules.

use std::collections::HashMap;

/// A point in pixel units: (0, 0) is the image's top-left corner, pixel (x, y) is the unit
/// square from (x, y) to (x + 1, y + 1).
pub type Point = [f64; 2];

/// A binary mask over a window of an image: `origin` is the window's top-left pixel.
pub struct MaskWindow {
    pub origin: [u32; 2],
    pub width: usize,
    pub height: usize,
    /// Row-major.
    pub pixels: Vec<bool>,
}

impl MaskWindow {
    fn inside(&self, x: i64, y: i64) -> bool {
        x >= 0
            && y >= 0
            && (x as usize) < self.width
            && (y as usize) < self.height
            && self.pixels[y as usize * self.width + x as usize]
    }

    /// The polygon of this mask, in image pixel units, and its IoU with the mask (rasterised at
    /// pixel centres, even-odd). Simplified as far as that IoU stays at least `min_iou`; the
    /// exact traced outline (IoU 1) where no simplification does. Empty for an empty mask.
    pub fn polygon(&self, min_iou: f64) -> (Vec<Point>, f64) {
        let rings: Vec<Vec<Point>> = trace_rings(self).iter().map(|r| inset(r)).collect();
        if rings.is_empty() {
            return (Vec::new(), 0.0);
        }
        // A small instance keeps its exact outline: a pixel there is a large share of its IoU,
        // and rasterisers differ most on the diagonals simplification makes.
        let area = self.pixels.iter().filter(|&&p| p).count();
        let epsilons: &[f64] = if area < SIMPLIFY_FROM { &[0.0] } else { &[1.0, 0.5, 0.0] };
        for &epsilon in epsilons {
            let polygon = join_rings(rings.iter().map(|r| simplify(r, epsilon)).collect());
            let iou = self.iou(&polygon);
            if iou >= min_iou || epsilon == 0.0 {
                let [x0, y0] = self.origin.map(f64::from);
                return (polygon.into_iter().map(|[x, y]| [x + x0, y + y0]).collect(), iou);
            }
        }
        unreachable!("the last epsilon always returns")
    }

    /// IoU of this mask and `polygon` (window coordinates) rasterised over the window.
    fn iou(&self, polygon: &[Point]) -> f64 {
        let filled = rasterize(polygon, self.width, self.height);
        let both = filled.iter().zip(&self.pixels).filter(|(a, b)| **a && **b).count();
        let either = filled.iter().zip(&self.pixels).filter(|(a, b)| **a || **b).count();
        if either == 0 {
            return 1.0;
        }
        both as f64 / either as f64
    }
}

/// Pixel centres inside `polygon` by the even-odd rule, over a `width`×`height` grid.
pub fn rasterize(polygon: &[Point], width: usize, height: usize) -> Vec<bool> {
    let mut filled = vec![false; width * height];
    let mut crossings = Vec::new();
    for row in 0..height {
        let yc = row as f64 + 0.5;
        crossings.clear();
        for (i, &[x1, y1]) in polygon.iter().enumerate() {
            let [x2, y2] = polygon[(i + 1) % polygon.len()];
            if (y1 <= yc) != (y2 <= yc) {
                crossings.push(x1 + (yc - y1) * (x2 - x1) / (y2 - y1));
            }
        }
        crossings.sort_by(f64::total_cmp);
        for pair in crossings.chunks_exact(2) {
            // Centres x + 0.5 in [pair[0], pair[1]).
            let first = (pair[0] - 0.5).ceil().max(0.0) as usize;
            let end = ((pair[1] - 0.5).ceil().max(0.0) as usize).min(width);
            filled[row * width..][first.min(end)..end].iter_mut().for_each(|p| *p = true);
        }
    }
    filled
}

/// The mask's boundary as closed rings of pixel corners, walked with the mask on the right (in
/// y-down coordinates), straight runs reduced to their ends.
fn trace_rings(mask: &MaskWindow) -> Vec<Vec<[i64; 2]>> {
    let mut out: HashMap<[i64; 2], Vec<[i64; 2]>> = HashMap::new();
    for y in 0..mask.height as i64 {
        for x in 0..mask.width as i64 {
            if !mask.inside(x, y) {
                continue;
            }
            let sides = [
                ((0, -1), [x, y], [x + 1, y]),
                ((1, 0), [x + 1, y], [x + 1, y + 1]),
                ((0, 1), [x + 1, y + 1], [x, y + 1]),
                ((-1, 0), [x, y + 1], [x, y]),
            ];
            for ((dx, dy), from, to) in sides {
                if !mask.inside(x + dx, y + dy) {
                    out.entry(from).or_default().push(to);
                }
            }
        }
    }
    let mut starts: Vec<[i64; 2]> = out.keys().copied().collect();
    starts.sort_unstable();
    let mut rings = Vec::new();
    for start in starts {
        while out.get(&start).is_some_and(|ends| !ends.is_empty()) {
            let mut ring = vec![start];
            let (mut at, mut heading) = (start, [0, 0]);
            loop {
                let ends = out.get_mut(&at).expect("every corner reached has its edge out");
                // Where two edges leave one corner (pixels touching diagonally), turn right:
                // the same choice at every such corner, so each ring closes.
                let pick = (0..ends.len())
                    .max_by_key(|&k| heading[0] * (ends[k][1] - at[1]) - heading[1] * (ends[k][0] - at[0]))
                    .expect("a corner with an edge out");
                let next = ends.swap_remove(pick);
                heading = [next[0] - at[0], next[1] - at[1]];
                at = next;
                if at == start {
                    break;
                }
                ring.push(at);
            }
            rings.push(corners_only(ring));
        }
    }
    rings
}

/// The ring without the points inside straight runs.
fn corners_only(ring: Vec<[i64; 2]>) -> Vec<[i64; 2]> {
    let n = ring.len();
    (0..n)
        .filter(|&i| {
            let (a, b, c) = (ring[(i + n - 1) % n], ring[i], ring[(i + 1) % n]);
            (b[0] - a[0]) * (c[1] - b[1]) != (b[1] - a[1]) * (c[0] - b[0])
        })
        .map(|i| ring[i])
        .collect()
}

/// The smallest mask, in pixels, whose outline is simplified.
const SIMPLIFY_FROM: usize = 200;

/// How far each traced ring is moved into its pixels: a YOLO trainer truncates a vertex to the
/// pixel it lies in and fills the polygon through pixel centres with its edges (Ultralytics'
/// `polygon2mask`, OpenCV's `fillPoly`), so an outline along pixel edges would grow by a pixel
/// on the right and bottom there; moved in by this much, it gives the mask back both there and
/// where pixel centres are tested against the polygon (pycocotools, our own [`rasterize`]).
const INSET: f64 = 0.05;

/// The ring (pixel corners, axis-aligned edges, the mask on the right) moved [`INSET`] into
/// the mask along both edges at each corner.
fn inset(ring: &[[i64; 2]]) -> Vec<Point> {
    let n = ring.len();
    // The right of heading (dx, dy) in y-down coordinates is (-dy, dx).
    let right = |a: [i64; 2], b: [i64; 2]| [-(b[1] - a[1]).signum() as f64, (b[0] - a[0]).signum() as f64];
    (0..n)
        .map(|i| {
            let (before, at, after) = (ring[(i + n - 1) % n], ring[i], ring[(i + 1) % n]);
            let (r1, r2) = (right(before, at), right(at, after));
            [at[0] as f64 + INSET * (r1[0] + r2[0]), at[1] as f64 + INSET * (r1[1] + r2[1])]
        })
        .collect()
}

/// Douglas–Peucker on a closed ring, cut at its first point and the point farthest from it;
/// `epsilon` 0 keeps the ring. Never fewer than 3 points.
fn simplify(ring: &[Point], epsilon: f64) -> Vec<Point> {
    let points = ring.to_vec();
    if epsilon == 0.0 || points.len() <= 4 {
        return points;
    }
    let far = (1..points.len())
        .max_by(|&a, &b| dist2(points[0], points[a]).total_cmp(&dist2(points[0], points[b])))
        .unwrap_or(1);
    let mut keep = vec![false; points.len()];
    keep[0] = true;
    keep[far] = true;
    let mut closed = points.clone();
    closed.push(points[0]);
    douglas_peucker(&closed, 0, far, epsilon, &mut keep);
    douglas_peucker(&closed, far, points.len(), epsilon, &mut keep);
    let kept: Vec<Point> = points.iter().zip(&keep).filter(|(_, k)| **k).map(|(p, _)| *p).collect();
    if kept.len() >= 3 {
        kept
    } else {
        points
    }
}

fn douglas_peucker(points: &[Point], first: usize, last: usize, epsilon: f64, keep: &mut [bool]) {
    if last <= first + 1 {
        return;
    }
    let (a, b) = (points[first], points[last]);
    let (k, d) = (first + 1..last)
        .map(|k| (k, distance_to_segment(points[k], a, b)))
        .max_by(|x, y| x.1.total_cmp(&y.1))
        .expect("a point between");
    if d > epsilon {
        keep[k % keep.len()] = true;
        douglas_peucker(points, first, k, epsilon, keep);
        douglas_peucker(points, k, last, epsilon, keep);
    }
}

fn dist2(a: Point, b: Point) -> f64 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)
}

fn distance_to_segment(p: Point, a: Point, b: Point) -> f64 {
    let len2 = dist2(a, b);
    if len2 == 0.0 {
        return dist2(p, a).sqrt();
    }
    let t = (((p[0] - a[0]) * (b[0] - a[0]) + (p[1] - a[1]) * (b[1] - a[1])) / len2).clamp(0.0, 1.0);
    dist2(p, [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]).sqrt()
}

/// The rings as one polygon: the largest first, each other ring spliced in at its point nearest
/// to what is joined so far, by a bridge walked there and back.
fn join_rings(mut rings: Vec<Vec<Point>>) -> Vec<Point> {
    rings.sort_by(|a, b| area(b).abs().total_cmp(&area(a).abs()));
    let mut rings = rings.into_iter();
    let mut joined = rings.next().unwrap_or_default();
    for ring in rings {
        let (i, j) = (0..joined.len())
            .flat_map(|i| (0..ring.len()).map(move |j| (i, j)))
            .min_by(|&(i, j), &(k, l)| dist2(joined[i], ring[j]).total_cmp(&dist2(joined[k], ring[l])))
            .expect("rings have points");
        let mut spliced = joined[..=i].to_vec();
        spliced.extend(&ring[j..]);
        spliced.extend(&ring[..=j]);
        spliced.extend(&joined[i..]);
        joined = spliced;
    }
    joined
}

/// Signed area (shoelace).
fn area(ring: &[Point]) -> f64 {
    (0..ring.len())
        .map(|i| {
            let (a, b) = (ring[i], ring[(i + 1) % ring.len()]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum::<f64>()
        / 2.0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn window(rows: &[&str]) -> MaskWindow {
        let pixels = rows.iter().flat_map(|r| r.chars().map(|c| c == '#')).collect();
        MaskWindow { origin: [10, 20], width: rows[0].len(), height: rows.len(), pixels }
    }

    fn assert_exact(mask: &MaskWindow) {
        assert_exact_at(mask, 1.0);
    }

    fn assert_exact_at(mask: &MaskWindow, min_iou: f64) {
        let (polygon, iou) = mask.polygon(min_iou);
        assert_eq!(iou, 1.0);
        let local: Vec<Point> = polygon.iter().map(|&[x, y]| [x - 10.0, y - 20.0]).collect();
        assert_eq!(rasterize(&local, mask.width, mask.height), mask.pixels);
    }

    #[test]
    fn holes_parts_and_diagonal_touches_come_back_exactly() {
        assert_exact(&window(&["#####", "#...#", "#.#.#", "#...#", "#####"]));
        assert_exact(&window(&["##...", "##...", ".....", "...##", "...##"]));
        assert_exact(&window(&["#.#.", ".#.#", "#.#.", "..##"]));
        assert_exact(&window(&["#"]));
    }

    /// Random masks (blobs, holes, diagonal touches, every kind of corner in both turning
    /// directions), all smaller than SIMPLIFY_FROM, come back exactly whatever IoU is asked.
    #[test]
    fn random_masks_come_back_exactly() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        for _ in 0..200 {
            let (w, h) = (1 + (state % 9) as usize, 1 + (state / 9 % 9) as usize);
            let pixels: Vec<bool> = (0..w * h)
                .map(|_| {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    state % 5 < 3
                })
                .collect();
            if pixels.iter().any(|&p| p) {
                assert_exact_at(&MaskWindow { origin: [10, 20], width: w, height: h, pixels }, 0.5);
            }
        }
    }

    #[test]
    fn a_disc_simplifies_to_few_points_and_keeps_its_area() {
        let n = 40;
        let rows: Vec<String> = (0..n)
            .map(|y| (0..n).map(|x| if (x as f64 - 19.5).hypot(y as f64 - 19.5) < 18.0 { '#' } else { '.' }).collect())
            .collect();
        let mask = window(&rows.iter().map(String::as_str).collect::<Vec<_>>());
        let (polygon, iou) = mask.polygon(0.9);
        assert!(iou > 0.95 && polygon.len() < 40, "{iou} with {} points", polygon.len());
        assert!(polygon.iter().all(|&[x, y]| (10.0..=50.0).contains(&x) && (20.0..=60.0).contains(&y)));
    }
}
