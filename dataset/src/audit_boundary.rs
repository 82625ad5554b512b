//! The audit's score that needs no model: how well the image's strong edges follow the instance
//! boundaries. Edges are Sobel's on the luminance, thinned to their ridge (non-maximum
//! suppression across the gradient) and kept where the gradient reaches a threshold; boundaries
//! are the instance pixels with a 4-neighbour of another id (background included, the image's
//! border not). Precision is the share of edges within the tolerance of a boundary, recall the
//! share of boundary pixels within the tolerance of an edge, F their harmonic mean: per image
//! over every edge and boundary, per instance over its own boundary and the edges within the
//! tolerance of its mask.

/// Precision, recall and F of one image or instance; `None` where there is nothing to measure.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct BoundaryScore {
    pub f: f64,
    pub precision: f64,
    pub recall: f64,
}

impl BoundaryScore {
    fn of(hits: (usize, usize), covered: (usize, usize)) -> Option<BoundaryScore> {
        if covered.1 == 0 {
            return None;
        }
        let precision = if hits.1 == 0 { 0.0 } else { hits.0 as f64 / hits.1 as f64 };
        let recall = covered.0 as f64 / covered.1 as f64;
        let f = if precision + recall == 0.0 { 0.0 } else { 2.0 * precision * recall / (precision + recall) };
        Some(BoundaryScore { f, precision, recall })
    }
}

/// A picture's strong edges, row-major: Sobel's magnitude on the luminance (0 to 1, divided by
/// 4 so that a unit step gives 1), kept on its ridge where it reaches `threshold`.
pub fn strong_edges(rgb: &[u8], width: usize, height: usize, threshold: f64) -> Vec<bool> {
    let luma: Vec<f64> =
        rgb.chunks(3).map(|p| (0.299 * p[0] as f64 + 0.587 * p[1] as f64 + 0.114 * p[2] as f64) / 255.0).collect();
    let at = |x: isize, y: isize| {
        luma[y.clamp(0, height as isize - 1) as usize * width + x.clamp(0, width as isize - 1) as usize]
    };
    let mut gx = vec![0.0; width * height];
    let mut gy = vec![0.0; width * height];
    for y in 0..height as isize {
        for x in 0..width as isize {
            let i = y as usize * width + x as usize;
            gx[i] = (at(x + 1, y - 1) + 2.0 * at(x + 1, y) + at(x + 1, y + 1)
                - at(x - 1, y - 1)
                - 2.0 * at(x - 1, y)
                - at(x - 1, y + 1))
                / 4.0;
            gy[i] = (at(x - 1, y + 1) + 2.0 * at(x, y + 1) + at(x + 1, y + 1)
                - at(x - 1, y - 1)
                - 2.0 * at(x, y - 1)
                - at(x + 1, y - 1))
                / 4.0;
        }
    }
    let magnitude: Vec<f64> = gx.iter().zip(&gy).map(|(a, b)| a.hypot(*b)).collect();
    let m = |x: isize, y: isize| {
        if x < 0 || y < 0 || x >= width as isize || y >= height as isize {
            0.0
        } else {
            magnitude[y as usize * width + x as usize]
        }
    };
    (0..width * height)
        .map(|i| {
            let (x, y) = ((i % width) as isize, (i / width) as isize);
            if magnitude[i] < threshold {
                return false;
            }
            // The neighbours across the edge: the gradient's direction in 45° sectors.
            let angle = gy[i].atan2(gx[i]).to_degrees().rem_euclid(180.0);
            let (dx, dy) = match angle {
                a if !(22.5..157.5).contains(&a) => (1, 0),
                a if a < 67.5 => (1, 1),
                a if a < 112.5 => (0, 1),
                _ => (-1, 1),
            };
            magnitude[i] >= m(x + dx, y + dy) && magnitude[i] >= m(x - dx, y - dy)
        })
        .collect()
}

/// Pixels of an instance (ids > 0 in `ids`, row-major) with a 4-neighbour of another id.
fn boundaries(ids: &[u32], width: usize, height: usize) -> Vec<bool> {
    (0..width * height)
        .map(|i| {
            let (x, y) = (i % width, i / width);
            ids[i] != 0
                && [
                    (x > 0).then(|| i - 1),
                    (x + 1 < width).then(|| i + 1),
                    (y > 0).then(|| i - width),
                    (y + 1 < height).then(|| i + width),
                ]
                .into_iter()
                .flatten()
                .any(|j| ids[j] != ids[i])
        })
        .collect()
}

/// The offsets within `tolerance` pixels (Euclidean) of a pixel.
fn disc(tolerance: u32) -> Vec<(isize, isize)> {
    let r = tolerance as isize;
    (-r..=r).flat_map(|dy| (-r..=r).map(move |dx| (dx, dy))).filter(|(dx, dy)| dx * dx + dy * dy <= r * r).collect()
}

/// The image's score and each instance's (ids 1 to `instances`), from its edges and the
/// instances' id map (0: background), both row-major.
pub fn boundary_scores(
    edges: &[bool],
    ids: &[u32],
    instances: usize,
    (width, height): (usize, usize),
    tolerance: u32,
) -> (Option<BoundaryScore>, Vec<Option<BoundaryScore>>) {
    let boundary = boundaries(ids, width, height);
    let disc = disc(tolerance);
    let around = |i: usize| {
        let (x, y) = ((i % width) as isize, (i / width) as isize);
        disc.iter().filter_map(move |&(dx, dy)| {
            let (u, v) = (x + dx, y + dy);
            (u >= 0 && v >= 0 && u < width as isize && v < height as isize).then(|| v as usize * width + u as usize)
        })
    };
    // [edges near its boundary, edges near its mask, boundary pixels near an edge, boundary
    // pixels], per instance id; index 0 the whole image's.
    let mut tallies = vec![[0usize; 4]; instances + 1];
    let (mut near_ids, mut boundary_ids) = (Vec::new(), Vec::new());
    for i in (0..edges.len()).filter(|&i| edges[i]) {
        near_ids.clear();
        boundary_ids.clear();
        for j in around(i) {
            near_ids.push(ids[j]);
            if boundary[j] {
                boundary_ids.push(ids[j]);
            }
        }
        near_ids.sort_unstable();
        near_ids.dedup();
        tallies[0][0] += !boundary_ids.is_empty() as usize;
        tallies[0][1] += 1;
        for &id in near_ids.iter().filter(|&&id| id != 0) {
            tallies[id as usize][1] += 1;
            tallies[id as usize][0] += boundary_ids.contains(&id) as usize;
        }
    }
    for i in (0..boundary.len()).filter(|&i| boundary[i]) {
        let seen = around(i).any(|j| edges[j]) as usize;
        for id in [0, ids[i] as usize] {
            tallies[id][2] += seen;
            tallies[id][3] += 1;
        }
    }
    let score = |t: &[usize; 4]| BoundaryScore::of((t[0], t[1]), (t[2], t[3]));
    (score(&tallies[0]), tallies[1..].iter().map(score).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grey square on black, its mask `shift` pixels to the right.
    fn square(shift: usize) -> (Vec<u8>, Vec<u32>) {
        let (w, h) = (40, 30);
        let mut rgb = vec![0u8; w * h * 3];
        let mut ids = vec![0u32; w * h];
        for y in 10..20 {
            for x in 10..25 {
                rgb[(y * w + x) * 3..][..3].copy_from_slice(&[200, 200, 200]);
                ids[y * w + x + shift] = 1;
            }
        }
        (rgb, ids)
    }

    #[test]
    fn a_mask_on_its_object_scores_one_and_a_shifted_one_less() {
        let score = |shift: usize, tolerance: u32| {
            let (rgb, ids) = square(shift);
            let edges = strong_edges(&rgb, 40, 30, 0.1);
            boundary_scores(&edges, &ids, 1, (40, 30), tolerance)
        };
        let (image, instances) = score(0, 2);
        assert_eq!(image.unwrap().f, 1.0);
        assert_eq!(instances, vec![image]);
        // Shifted by 2: still within the tolerance of 2; at 1, its left side is off its edge.
        assert_eq!(score(2, 2).1[0].unwrap().recall, 1.0);
        assert_eq!(score(0, 1).1[0].unwrap().recall, 1.0);
        let off = score(2, 1).1[0].unwrap().recall;
        assert!(off < 0.9 && off > 0.5, "{off}");
        // Shifted by 5: only the top and bottom edges, away from the sides, still agree.
        let far = score(5, 2).1[0].unwrap();
        assert!(far.f < 0.8 && far.f > 0.3, "{far:?}");
    }

    #[test]
    fn an_object_painted_over_has_no_boundary_support() {
        let (_, ids) = square(0);
        let edges = strong_edges(&vec![0u8; 40 * 30 * 3], 40, 30, 0.1);
        let (image, instances) = boundary_scores(&edges, &ids, 1, (40, 30), 2);
        assert_eq!(image.unwrap().recall, 0.0);
        assert_eq!(instances[0].unwrap().f, 0.0);
    }

    #[test]
    fn edges_are_thin_and_only_where_the_gradient_is_strong() {
        let (rgb, _) = square(0);
        let edges = strong_edges(&rgb, 40, 30, 0.1);
        // The left side: a ridge one or two pixels wide at the step (x 9 to 10), nothing further.
        let row: Vec<usize> = (0..40).filter(|&x| edges[15 * 40 + x]).collect();
        assert!(row.iter().all(|&x| (9..=10).contains(&x) || (24..=25).contains(&x)), "{row:?}");
        assert!(strong_edges(&rgb, 40, 30, 0.9).iter().all(|&e| !e));
    }
}
