//! The compost ground: a height field with a few millimetres of relief (broad undulation plus
//! crumbly clods), meshed on a grid whose spacing follows the pixel size, so the depth map shows
//! the texture of the casing without spending triangles finer than a pixel.

use rayon::prelude::*;

use crate::math::Vec3;
use crate::mesh::Mesh;
use crate::noise::GradientNoise;
use crate::poisson::Rect;

/// Grid spacing of the ground mesh in pixels of the camera looking at it.
pub const GROUND_CELL_PX: f64 = 6.0;

#[derive(Clone, Copy, Debug)]
pub struct Compost {
    noise: GradientNoise,
}

impl Compost {
    /// Relief of the broad undulation and of the clods, metres (peak, roughly).
    const UNDULATION: (f64, f64) = (0.002, 0.060); // (amplitude, wavelength)
    const CLODS: (f64, f64) = (0.0016, 0.012);

    pub fn new(seed: u64) -> Self {
        Compost { noise: GradientNoise::new(seed) }
    }

    /// Surface height at (x, y), metres.
    pub fn height(&self, x: f64, y: f64) -> f64 {
        let (a, wavelength) = Self::UNDULATION;
        let undulation = a * self.noise.fractal(x / wavelength, y / wavelength, 2, 0.5, |v| v);
        // Billowed noise (|v|) has rounded bumps and sharp creases: clods of casing soil.
        let (a, wavelength) = Self::CLODS;
        let clods = a * self.noise.fractal(x / wavelength + 101.0, y / wavelength, 3, 0.5, |v| 1.0 - 2.0 * v.abs());
        undulation + clods
    }

    /// Grid mesh over `region` with cells of about `spacing` metres.
    pub fn mesh(&self, region: Rect, spacing: f64) -> Mesh {
        let columns = ((region.x1 - region.x0) / spacing).ceil() as usize + 1;
        let rows = ((region.y1 - region.y0) / spacing).ceil() as usize + 1;
        let (dx, dy) = ((region.x1 - region.x0) / (columns - 1) as f64, (region.y1 - region.y0) / (rows - 1) as f64);
        let positions = (0..rows * columns)
            .into_par_iter()
            .map(|i| {
                let (x, y) = (region.x0 + (i % columns) as f64 * dx, region.y0 + (i / columns) as f64 * dy);
                Vec3::new(x, y, self.height(x, y))
            })
            .collect();
        let mut mesh = Mesh { positions, triangles: Vec::with_capacity(2 * rows * columns) };
        let at = |r: usize, c: usize| (r * columns + c) as u32;
        for r in 0..rows - 1 {
            for c in 0..columns - 1 {
                // Counter-clockwise seen from above: the up side faces the camera.
                mesh.triangles.push([at(r, c), at(r, c + 1), at(r + 1, c + 1)]);
                mesh.triangles.push([at(r, c), at(r + 1, c + 1), at(r + 1, c)]);
            }
        }
        mesh
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relief_is_a_few_millimetres_and_mesh_faces_up() {
        let compost = Compost::new(11);
        let heights: Vec<f64> =
            (0..10_000).map(|i| compost.height((i % 100) as f64 * 0.003, (i / 100) as f64 * 0.003)).collect();
        let (lo, hi) = heights.iter().fold((f64::MAX, f64::MIN), |(lo, hi), &h| (lo.min(h), hi.max(h)));
        assert!(hi - lo > 0.002 && hi - lo < 0.010, "relief {} mm", (hi - lo) * 1e3);
        let mesh = compost.mesh(Rect { x0: 0.0, y0: 0.0, x1: 0.05, y1: 0.03 }, 0.002);
        assert_eq!(mesh.positions.len(), 26 * 16);
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
            assert!((b - a).cross(c - a).z > 0.0);
        }
    }
}
