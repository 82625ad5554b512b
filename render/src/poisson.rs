//! Variable-radius Poisson-disk sampling with the clumping of a real mushroom bed.
//!
//! Proposals come from a Thomas cluster process (Gaussian clumps around random parents, plus a
//! share of uniform ones), then pass a hard-core test in order of decreasing size ("dart
//! throwing", Cook 1986, with per-pair radii): big caps claim their place first and small ones
//! fill in around them. A proposal that lands on an accepted disk is nudged out until it touches
//! it, a few times at most, which is what makes big caps touch and pins crowd round their feet,
//! instead of the even spacing of plain blue noise.

use crate::rng::Rng;

/// An axis-aligned rectangle on the ground plane, metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rect {
    pub x0: f64,
    pub y0: f64,
    pub x1: f64,
    pub y1: f64,
}

impl Rect {
    pub fn area(&self) -> f64 {
        (self.x1 - self.x0) * (self.y1 - self.y0)
    }
    pub fn contains(&self, x: f64, y: f64) -> bool {
        (self.x0..=self.x1).contains(&x) && (self.y0..=self.y1).contains(&y)
    }
    pub fn grown(&self, margin: f64) -> Rect {
        Rect { x0: self.x0 - margin, y0: self.y0 - margin, x1: self.x1 + margin, y1: self.y1 + margin }
    }
}

/// The share of the smaller disk's radius that must stay outside the larger one: equal caps may
/// press into each other by a fifth of their radius, a pin may hide two thirds of itself under a
/// cap.
pub fn min_distance(ra: f64, rb: f64) -> f64 {
    let (big, small) = if ra >= rb { (ra, rb) } else { (rb, ra) };
    let similarity = if big > 0.0 { small / big } else { 1.0 };
    big + small * (0.35 + 0.45 * similarity)
}

/// How proposals cluster.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Clumping {
    /// Share of proposals drawn around cluster parents; the rest fall uniformly.
    pub clustered_fraction: f64,
    pub clusters_per_m2: f64,
    /// Standard deviation of a clump's Gaussian, metres.
    pub cluster_sigma: f64,
}

/// `count` proposal points in `region` from a Thomas process whose parents have exponentially
/// distributed weights, so clumps come in very different sizes as on a real bed.
pub fn clustered_points(rng: &mut Rng, region: Rect, count: usize, clumping: &Clumping) -> Vec<(f64, f64)> {
    let uniform = |rng: &mut Rng| (rng.range(region.x0, region.x1), rng.range(region.y0, region.y1));
    let parents = ((clumping.clusters_per_m2 * region.area()).round() as usize).max(1);
    let centres: Vec<(f64, f64)> = (0..parents).map(|_| uniform(rng)).collect();
    let mut cumulative = Vec::with_capacity(parents);
    let mut total = 0.0;
    for _ in 0..parents {
        total += -(1.0 - rng.uniform()).ln();
        cumulative.push(total);
    }
    (0..count)
        .map(|_| {
            if rng.uniform() >= clumping.clustered_fraction {
                return uniform(rng);
            }
            let pick = rng.uniform() * total;
            let (cx, cy) = centres[cumulative.partition_point(|&c| c <= pick).min(parents - 1)];
            // Redraw offsets that leave the region (at most a few times), so clumps at the edge
            // keep their shape instead of piling up on the border.
            for _ in 0..8 {
                let (x, y) = (cx + clumping.cluster_sigma * rng.normal(), cy + clumping.cluster_sigma * rng.normal());
                if region.contains(x, y) {
                    return (x, y);
                }
            }
            (cx, cy)
        })
        .collect()
}

/// A disk that passed the hard-core test: which proposal it was, and where it ended up.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placed {
    pub index: usize,
    pub x: f64,
    pub y: f64,
    pub radius: f64,
}

const MAX_NUDGES: usize = 3;

/// Hard-core selection of proposals `(x, y, radius)` inside `region`, largest first (ties by
/// index). Every pair of returned disks is at least `min_distance` apart.
pub fn place_disks(proposals: &[(f64, f64, f64)], region: Rect) -> Vec<Placed> {
    let mut order: Vec<usize> = (0..proposals.len()).collect();
    order.sort_by(|&a, &b| proposals[b].2.total_cmp(&proposals[a].2).then(a.cmp(&b)));
    let max_radius = proposals.iter().map(|p| p.2).fold(0.0, f64::max);
    // Cells no finer than 1/1024 of the region keep the grid small whatever the radii.
    let extent = (region.x1 - region.x0).max(region.y1 - region.y0);
    let mut grid = Grid::new(region, (2.0 * max_radius).max(extent / 1024.0));
    let mut placed: Vec<Placed> = Vec::new();
    for index in order {
        let (mut x, mut y, radius) = proposals[index];
        for attempt in 0..=MAX_NUDGES {
            let Some(blocker) = grid.deepest_overlap(&placed, x, y, radius) else {
                grid.insert(placed.len(), x, y);
                placed.push(Placed { index, x, y, radius });
                break;
            };
            if attempt == MAX_NUDGES {
                break;
            }
            // Push the proposal straight away from the disk it overlaps most, to touching.
            let b = placed[blocker];
            let (dx, dy) = (x - b.x, y - b.y);
            let len = dx.hypot(dy);
            let (ux, uy) = if len > 0.0 { (dx / len, dy / len) } else { golden_direction(index) };
            let reach = min_distance(radius, b.radius) * (1.0 + 1e-9);
            (x, y) = (b.x + ux * reach, b.y + uy * reach);
            if !region.contains(x, y) {
                break;
            }
        }
    }
    placed.sort_by_key(|p| p.index);
    placed
}

/// A direction that depends only on the proposal's index, for the rare exact coincidence.
fn golden_direction(index: usize) -> (f64, f64) {
    let angle = index as f64 * 2.399_963_229_728_653; // golden angle
    (angle.cos(), angle.sin())
}

/// Uniform bucket grid whose cells are at least as wide as any interaction distance, so a query
/// only looks at the 3×3 cells around a point.
struct Grid {
    region: Rect,
    cell: f64,
    columns: usize,
    rows: usize,
    buckets: Vec<Vec<usize>>,
}

impl Grid {
    fn new(region: Rect, cell: f64) -> Grid {
        let columns = ((region.x1 - region.x0) / cell).ceil().max(1.0) as usize;
        let rows = ((region.y1 - region.y0) / cell).ceil().max(1.0) as usize;
        Grid { region, cell, columns, rows, buckets: vec![Vec::new(); columns * rows] }
    }

    fn cell_of(&self, x: f64, y: f64) -> (usize, usize) {
        let c = ((x - self.region.x0) / self.cell).floor().clamp(0.0, (self.columns - 1) as f64);
        let r = ((y - self.region.y0) / self.cell).floor().clamp(0.0, (self.rows - 1) as f64);
        (c as usize, r as usize)
    }

    fn insert(&mut self, id: usize, x: f64, y: f64) {
        let (c, r) = self.cell_of(x, y);
        self.buckets[r * self.columns + c].push(id);
    }

    /// The placed disk that a disk at (x, y) would overlap most, if any.
    fn deepest_overlap(&self, placed: &[Placed], x: f64, y: f64, radius: f64) -> Option<usize> {
        let (c, r) = self.cell_of(x, y);
        let mut deepest: Option<(f64, usize)> = None;
        for row in r.saturating_sub(1)..=(r + 1).min(self.rows - 1) {
            for col in c.saturating_sub(1)..=(c + 1).min(self.columns - 1) {
                for &id in &self.buckets[row * self.columns + col] {
                    let p = &placed[id];
                    let depth = min_distance(radius, p.radius) - (x - p.x).hypot(y - p.y);
                    if depth > 0.0 && deepest.is_none_or(|(d, _)| depth > d) {
                        deepest = Some((depth, id));
                    }
                }
            }
        }
        deepest.map(|(_, id)| id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const REGION: Rect = Rect { x0: -0.2, y0: -0.1, x1: 0.2, y1: 0.1 };
    const CLUMPED: Clumping = Clumping { clustered_fraction: 0.8, clusters_per_m2: 60.0, cluster_sigma: 0.02 };

    fn proposals(seed: u64, count: usize, clumping: &Clumping) -> Vec<(f64, f64, f64)> {
        let mut rng = Rng::new(seed);
        let points = clustered_points(&mut rng, REGION, count, clumping);
        points.into_iter().map(|(x, y)| (x, y, rng.range(0.00075, 0.015))).collect()
    }

    #[test]
    fn every_pair_keeps_its_minimum_distance() {
        for seed in 0..5 {
            let placed = place_disks(&proposals(seed, 600, &CLUMPED), REGION);
            assert!(placed.len() > 100, "only {} placed", placed.len());
            for (i, a) in placed.iter().enumerate() {
                assert!(REGION.contains(a.x, a.y));
                for b in &placed[i + 1..] {
                    let d = (a.x - b.x).hypot(a.y - b.y);
                    assert!(d >= min_distance(a.radius, b.radius), "{a:?} and {b:?} are {d} apart");
                }
            }
        }
    }

    #[test]
    fn nudging_makes_neighbours_touch() {
        let placed = place_disks(&proposals(1, 600, &CLUMPED), REGION);
        let touching = placed
            .iter()
            .filter(|a| {
                placed.iter().any(|b| {
                    let d = (a.x - b.x).hypot(a.y - b.y);
                    a.index != b.index && d < min_distance(a.radius, b.radius) * 1.001
                })
            })
            .count();
        assert!(touching * 3 > placed.len(), "{touching} of {} touch a neighbour", placed.len());
    }

    /// Clark–Evans ratio: mean nearest-neighbour distance over its value for complete spatial
    /// randomness; below 1 means clustered.
    fn clark_evans(points: &[(f64, f64)]) -> f64 {
        let mean_nn = points
            .iter()
            .enumerate()
            .map(|(i, a)| {
                points
                    .iter()
                    .enumerate()
                    .filter(|&(j, _)| j != i)
                    .map(|(_, b)| (a.0 - b.0).hypot(a.1 - b.1))
                    .fold(f64::MAX, f64::min)
            })
            .sum::<f64>()
            / points.len() as f64;
        mean_nn / (0.5 / (points.len() as f64 / REGION.area()).sqrt())
    }

    #[test]
    fn proposals_clump_only_when_asked() {
        let none = Clumping { clustered_fraction: 0.0, ..CLUMPED };
        let uniform = clark_evans(&clustered_points(&mut Rng::new(2), REGION, 800, &none));
        let clumped = clark_evans(&clustered_points(&mut Rng::new(2), REGION, 800, &CLUMPED));
        assert!((uniform - 1.0).abs() < 0.1, "uniform ratio {uniform}");
        assert!(clumped < 0.8, "clumped ratio {clumped}");
    }

    #[test]
    fn min_distance_lets_pins_tuck_under_caps() {
        assert!((min_distance(1.0, 1.0) - 1.8).abs() < 1e-12);
        assert!((min_distance(0.05, 1.0) - (1.0 + 0.05 * (0.35 + 0.45 * 0.05))).abs() < 1e-12);
        assert_eq!(min_distance(0.3, 0.7), min_distance(0.7, 0.3));
    }
}
