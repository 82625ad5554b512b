//! Seeded 2D gradient noise (Perlin's improved noise, with hashed lattice gradients instead of a
//! permutation table, so any seed gives an independent field without allocating).

use crate::rng::mix64;

const DIAGONAL: f64 = std::f64::consts::FRAC_1_SQRT_2;
/// Eight unit gradients: cheap to look up, and isotropic enough for a compost surface.
const GRADIENTS: [(f64, f64); 8] = [
    (1.0, 0.0),
    (-1.0, 0.0),
    (0.0, 1.0),
    (0.0, -1.0),
    (DIAGONAL, DIAGONAL),
    (-DIAGONAL, DIAGONAL),
    (DIAGONAL, -DIAGONAL),
    (-DIAGONAL, -DIAGONAL),
];

/// `x.floor()` as an integer, without the libm call baseline x86-64 makes of `floor`.
fn floor_i64(x: f64) -> i64 {
    let t = x as i64;
    t - i64::from((t as f64) > x)
}

#[derive(Clone, Copy, Debug)]
pub struct GradientNoise {
    seed: u64,
}

impl GradientNoise {
    pub fn new(seed: u64) -> Self {
        GradientNoise { seed: mix64(seed) }
    }

    fn corner(&self, ix: i64, iy: i64, fx: f64, fy: f64) -> f64 {
        let h = mix64(
            self.seed
                ^ (ix as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
                ^ (iy as u64).wrapping_mul(0xc2b2_ae3d_27d4_eb4f),
        );
        let (gx, gy) = GRADIENTS[(h >> 61) as usize];
        gx * fx + gy * fy
    }

    /// Noise at (x, y) in lattice units; zero on lattice points, within about ±1.
    pub fn sample(&self, x: f64, y: f64) -> f64 {
        let (ix, iy) = (floor_i64(x), floor_i64(y));
        let (fx, fy) = (x - ix as f64, y - iy as f64);
        let fade = |t: f64| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
        let (sx, sy) = (fade(fx), fade(fy));
        let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
        let bottom = lerp(self.corner(ix, iy, fx, fy), self.corner(ix + 1, iy, fx - 1.0, fy), sx);
        let top = lerp(self.corner(ix, iy + 1, fx, fy - 1.0), self.corner(ix + 1, iy + 1, fx - 1.0, fy - 1.0), sx);
        lerp(bottom, top, sy)
    }

    /// Fractal sum of `octaves` layers, each at twice the frequency and `gain` times the
    /// amplitude of the last; `shape` turns each layer's value into what is summed.
    pub fn fractal(&self, x: f64, y: f64, octaves: u32, gain: f64, shape: impl Fn(f64) -> f64) -> f64 {
        let (mut sum, mut amplitude, mut frequency) = (0.0, 1.0, 1.0);
        for octave in 0..octaves {
            // Offset each octave so the lattice zeros of different octaves never line up.
            let shift = 17.31 * octave as f64;
            sum += amplitude * shape(self.sample(x * frequency + shift, y * frequency - shift));
            amplitude *= gain;
            frequency *= 2.0;
        }
        sum
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn continuous_bounded_seeded() {
        let n = GradientNoise::new(5);
        let mut max: f64 = 0.0;
        let mut sum = 0.0;
        for i in 0..20_000 {
            let (x, y) = (i as f64 * 0.0137, (i % 97) as f64 * 0.31);
            let v = n.sample(x, y);
            max = max.max(v.abs());
            sum += v;
            assert!((n.sample(x + 1e-7, y) - v).abs() < 1e-5, "continuity at ({x}, {y})");
        }
        assert!(max < 1.0 && max > 0.3, "range {max}");
        assert!((sum / 20_000.0).abs() < 0.05, "mean {}", sum / 20_000.0);
        assert_eq!(n.sample(3.0, -2.0), 0.0);
        assert_ne!(n.sample(0.4, 0.6), GradientNoise::new(6).sample(0.4, 0.6));
    }
}
