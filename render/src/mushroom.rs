//! A procedural white button mushroom (*Agaricus bisporus*) with a closed cap, as in the paper's
//! Geometry Nodes model: `age` sets the size and the growth-stage proportions, `randomness`
//! scales the individual deviation of stem length and cap shape, `seed` picks that deviation.
//!
//! Proportions follow the real growth stages: a pin is a nearly spherical cap sitting on a short
//! stem it almost covers; a button is a dome wider than it is tall, with a thicker-looking stem
//! showing below an inrolled margin. The cap stays closed (veil intact, no gills) at every age.

use crate::error::{RenderError, Result};
use crate::mesh::{revolve, Mesh, ProfilePoint};
use crate::rng::Rng;

pub const MIN_AGE: f64 = 0.05;
pub const MAX_AGE: f64 = 1.0;
/// Cap diameter at age 1; the paper maps age linearly, 0.05 → 1.5 mm and 1 → 30 mm.
pub const FULL_CAP_DIAMETER_M: f64 = 0.030;
/// How far the stem reaches below the ground, so that tilt never lifts its base into view.
const STEM_EMBED_M: f64 = 0.003;

/// The four parameters of the paper's mushroom node group.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MushroomParams {
    pub age: f64,
    pub randomness: f64,
    pub seed: u64,
}

/// The dimensions of one mushroom in metres, in its own frame: z up, the stem axis through the
/// origin, the origin where the stem meets the ground.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Morphology {
    /// Radius of the cap at its widest (the equator).
    pub cap_radius: f64,
    /// Height of the dome above the equator.
    pub dome_height: f64,
    /// Drop from the equator down to the inrolled margin.
    pub margin_drop: f64,
    /// Exponent of the dome's superellipse: 1 is an ellipse, below 1 a flatter, fuller top.
    pub dome_exponent: f64,
    pub stem_radius: f64,
    /// Radius where the margin meets the veil, just outside the stem.
    pub margin_radius: f64,
    /// Visible stem: ground to margin.
    pub stem_length: f64,
    /// Amplitude and phase of the 2- and 3-lobed irregularity of the cap outline.
    pub lobes: [(f64, f64); 2],
}

impl MushroomParams {
    pub fn validate(&self) -> Result<()> {
        if !(MIN_AGE..=MAX_AGE).contains(&self.age) {
            return Err(RenderError::invalid("age", self.age, format!("must lie in [{MIN_AGE}, {MAX_AGE}]")));
        }
        if !(0.0..=1.0).contains(&self.randomness) {
            return Err(RenderError::invalid("randomness", self.randomness, "must lie in [0, 1]"));
        }
        Ok(())
    }

    /// The same individual `increment` later: how the node group chains growth stages.
    pub fn grown(&self, increment: f64) -> MushroomParams {
        MushroomParams { age: (self.age + increment).min(MAX_AGE), ..*self }
    }

    pub fn cap_diameter(&self) -> f64 {
        FULL_CAP_DIAMETER_M * self.age
    }

    pub fn morphology(&self) -> Morphology {
        // Growth stage: 0 for a pin, 1 once the button shape has settled (about 16 mm caps).
        let g = ((self.age - MIN_AGE) / (MAX_AGE - MIN_AGE)).clamp(0.0, 1.0);
        let stage = smoothstep(g / 0.55);
        let lerp = |pin: f64, button: f64| pin + (button - pin) * stage;
        // The individual's deviations come from the seed alone, so one seed grown through all
        // ages keeps its character (a row of the paper's bed).
        let mut rng = Rng::new(self.seed);
        let mut deviation = |scale: f64| 1.0 + self.randomness * scale * rng.normal().clamp(-2.5, 2.5);
        let stem_factor = deviation(0.4);
        let dome_factor = deviation(0.25);
        let exponent_factor = deviation(0.15);
        let mut lobe = || (self.randomness * 0.06 * rng.normal().abs().min(2.5), rng.range(0.0, std::f64::consts::TAU));
        let lobes = [lobe(), lobe()];

        let cap_radius = self.cap_diameter() / 2.0;
        let stem_radius = cap_radius * lerp(0.62, 0.42);
        Morphology {
            cap_radius,
            dome_height: cap_radius * lerp(0.95, 0.70) * dome_factor,
            margin_drop: cap_radius * lerp(0.62, 0.30) * dome_factor,
            dome_exponent: lerp(1.0, 0.82) * exponent_factor,
            stem_radius,
            margin_radius: stem_radius * 1.12,
            stem_length: (2.0 * cap_radius * lerp(0.10, 0.30) * stem_factor).max(0.02 * cap_radius),
            lobes,
        }
    }
}

/// Mesh detail for a cap that spans a given number of pixels on screen: edges of a few pixels, so
/// a 4-pixel pin is a handful of triangles and an 80-pixel cap still has a smooth silhouette.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Lod {
    pub segments: usize,
    pub dome_rings: usize,
    pub margin_rings: usize,
}

impl Lod {
    const TARGET_EDGE_PX: f64 = 4.0;

    pub fn for_cap_pixels(cap_px: f64) -> Lod {
        let segments = ((std::f64::consts::PI * cap_px / Self::TARGET_EDGE_PX).round() as usize).clamp(8, 48);
        Lod { segments, dome_rings: (segments / 4).clamp(2, 12), margin_rings: (segments / 8).clamp(1, 6) }
    }
}

impl Morphology {
    /// The outline in the (r, z) half-plane from the top of the cap down the dome, round the
    /// inrolled margin, across the veil to the stem, and down the stem to below the ground.
    pub fn profile(&self, lod: Lod) -> Vec<ProfilePoint> {
        let quarter = std::f64::consts::FRAC_PI_2;
        let equator = self.stem_length + self.margin_drop;
        let mut profile = Vec::with_capacity(lod.dome_rings + lod.margin_rings + 3);
        for k in 0..=lod.dome_rings {
            let theta = quarter * k as f64 / lod.dome_rings as f64;
            let q = self.dome_exponent;
            let r = if k == 0 { 0.0 } else { self.cap_radius * theta.sin().powf(q) };
            profile.push(ProfilePoint { r, z: equator + self.dome_height * theta.cos().max(0.0).powf(q) });
        }
        for k in 1..=lod.margin_rings {
            let phi = quarter * k as f64 / lod.margin_rings as f64;
            let r = self.margin_radius + (self.cap_radius - self.margin_radius) * phi.cos();
            profile.push(ProfilePoint { r, z: equator - self.margin_drop * phi.sin() });
        }
        profile.push(ProfilePoint { r: self.stem_radius, z: self.stem_length });
        let embed = STEM_EMBED_M + 0.2 * self.stem_radius;
        profile.push(ProfilePoint { r: self.stem_radius * 1.08, z: -embed });
        profile
    }

    pub fn mesh(&self, lod: Lod) -> Mesh {
        let span = self.cap_radius - self.margin_radius;
        revolve(&self.profile(lod), lod.segments, |phi, r| {
            // The lobes fade out towards the margin so the cap never cuts into the stem.
            let fade = ((r - self.margin_radius) / span).clamp(0.0, 1.0);
            let wobble: f64 = self.lobes.iter().zip([2.0, 3.0]).map(|(&(a, p), k)| a * (k * phi + p).cos()).sum();
            1.0 + fade * wobble
        })
    }

    /// Cap height: from the margin to the top of the dome.
    pub fn cap_height(&self) -> f64 {
        self.margin_drop + self.dome_height
    }
}

fn smoothstep(t: f64) -> f64 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(age: f64, randomness: f64, seed: u64) -> MushroomParams {
        MushroomParams { age, randomness, seed }
    }

    /// Widest horizontal extent of the mesh, measured through the axis.
    fn mesh_diameter(mesh: &Mesh) -> f64 {
        2.0 * mesh.positions.iter().map(|p| p.x.hypot(p.y)).fold(0.0, f64::max)
    }

    #[test]
    fn cap_diameter_follows_age_linearly_from_1_5_to_30_mm() {
        for i in 0..=19 {
            let age = MIN_AGE + 0.05 * i as f64;
            let mesh = params(age, 0.0, 3).morphology().mesh(Lod::for_cap_pixels(80.0));
            let expected = 0.0015 + (age - 0.05) / 0.95 * (0.030 - 0.0015);
            assert!((mesh_diameter(&mesh) - expected).abs() < 1e-9, "age {age}: {}", mesh_diameter(&mesh));
        }
        // Randomness makes caps irregular, but the 2- and 3-lobed wobble stays within a few percent.
        for seed in 0..50 {
            let d = mesh_diameter(&params(0.6, 0.25, seed).morphology().mesh(Lod::for_cap_pixels(60.0)));
            assert!((d / 0.018 - 1.0).abs() < 0.08, "seed {seed}: {d}");
        }
    }

    #[test]
    fn pins_are_nearly_spherical_and_buttons_domed() {
        let pin = params(MIN_AGE, 0.0, 1).morphology();
        let pin_height = pin.cap_height() + pin.stem_length;
        assert!(pin_height / (2.0 * pin.cap_radius) > 0.8, "a pin is about as tall as it is wide");
        assert!(pin.stem_length < 0.3 * pin.cap_height(), "a pin's cap nearly covers its stem");
        let button = params(MAX_AGE, 0.0, 1).morphology();
        let diameter = 2.0 * button.cap_radius;
        assert!(button.cap_height() < 0.6 * diameter && button.cap_height() > 0.4 * diameter, "domed cap");
        assert!(button.stem_length < diameter, "cap diameter exceeds the stem height");
        for m in [pin, button] {
            assert!(m.margin_radius > m.stem_radius && m.margin_radius < m.cap_radius, "closed cap");
        }
    }

    #[test]
    fn randomness_scales_deviation_and_seed_fixes_it() {
        let spread = |randomness: f64| {
            let lengths: Vec<f64> = (0..200).map(|s| params(0.5, randomness, s).morphology().stem_length).collect();
            let mean = lengths.iter().sum::<f64>() / lengths.len() as f64;
            (lengths.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / lengths.len() as f64).sqrt() / mean
        };
        assert!(spread(0.0) < 1e-12, "no randomness, no deviation");
        assert!(spread(0.25) > 0.05 && spread(1.0) > 3.0 * spread(0.25));
        let lod = Lod::for_cap_pixels(40.0);
        assert_eq!(params(0.5, 0.25, 9).morphology().mesh(lod), params(0.5, 0.25, 9).morphology().mesh(lod));
        assert_ne!(params(0.5, 0.25, 9).morphology(), params(0.5, 0.25, 10).morphology());
    }

    #[test]
    fn chaining_increments_reaches_the_same_individual_later() {
        let start = params(0.05, 0.25, 4);
        let later = (0..19).fold(start, |p, _| p.grown(0.05));
        assert!((later.age - 1.0).abs() < 1e-12 && later.seed == 4);
        assert_eq!(later.grown(0.5).age, MAX_AGE);
        assert!(params(1.2, 0.0, 0).validate().is_err() && params(0.5, -0.1, 0).validate().is_err());
    }

    #[test]
    fn detail_follows_screen_size() {
        let pin = Lod::for_cap_pixels(4.0);
        let cap = Lod::for_cap_pixels(80.0);
        assert_eq!(pin.segments, 8);
        assert!(cap.segments > 4 * pin.segments / 2 && cap.dome_rings > pin.dome_rings);
    }
}
