//! The mushroom bed of the paper: four rows of growth stages (20 stages each, one seed per row,
//! randomness 0.25: 80 variants), instances drawn at random from them, placed by clumped
//! Poisson-disk sampling on the compost, turned by a uniform yaw and tilted by up to ±10°.

use crate::camera::Camera;
use crate::error::{RenderError, Result};
use crate::ground::{Compost, GROUND_CELL_PX};
use crate::math::{Mat3, Vec3};
use crate::mesh::Mesh;
use crate::mushroom::{Lod, Morphology, MushroomParams, MIN_AGE};
use crate::poisson::{clustered_points, place_disks, Clumping, Rect};
use crate::rng::{Rng, Stream};

#[derive(Clone, Debug, PartialEq)]
pub struct BedConfig {
    /// Mushrooms proposed per square metre of bed; the hard-core test keeps most of them.
    pub density: f64,
    pub clumping: Clumping,
    pub rows: usize,
    pub stages: usize,
    pub first_age: f64,
    pub age_increment: f64,
    pub randomness: f64,
    pub max_tilt_deg: f64,
}

impl Default for BedConfig {
    fn default() -> Self {
        BedConfig {
            density: 552.0,
            clumping: Clumping { clustered_fraction: 0.8, clusters_per_m2: 40.0, cluster_sigma: 0.03 },
            rows: 4,
            stages: 20,
            first_age: MIN_AGE,
            age_increment: 0.05,
            randomness: 0.25,
            max_tilt_deg: 10.0,
        }
    }
}

impl BedConfig {
    pub fn validate(&self) -> Result<()> {
        if !(self.density.is_finite() && self.density >= 0.0) {
            return Err(RenderError::invalid("density", self.density, "must be a number ≥ 0 (mushrooms per m²)"));
        }
        if !(0.0..=1.0).contains(&self.clumping.clustered_fraction) {
            return Err(RenderError::invalid("clumping", self.clumping.clustered_fraction, "must lie in [0, 1]"));
        }
        MushroomParams { age: self.first_age, randomness: self.randomness, seed: 0 }.validate()
    }
}

/// One of the pre-built mushroom models instances are drawn from.
#[derive(Clone, Debug)]
pub struct Variant {
    pub row: usize,
    pub stage: usize,
    pub params: MushroomParams,
    pub morphology: Morphology,
    pub mesh: Mesh,
}

/// One mushroom on the bed.
#[derive(Clone, Debug, PartialEq)]
pub struct Instance {
    pub variant: usize,
    /// Where the stem axis meets the compost.
    pub base: Vec3,
    pub yaw: f64,
    /// Tilts about the world x and y axes, radians.
    pub tilt: (f64, f64),
}

impl Instance {
    pub fn rotation(&self) -> Mat3 {
        Mat3::rot_z(self.yaw) * Mat3::rot_x(self.tilt.0) * Mat3::rot_y(self.tilt.1)
    }

    pub fn to_world(&self, rotation: &Mat3, local: Vec3) -> Vec3 {
        self.base + rotation.apply(local)
    }
}

#[derive(Clone, Debug)]
pub struct Bed {
    pub variants: Vec<Variant>,
    pub instances: Vec<Instance>,
    pub ground: Mesh,
}

impl Bed {
    /// The bed seen by `camera`, from `seed` alone: the same seed and configuration give the same
    /// bed, mesh for mesh.
    pub fn generate(seed: u64, config: &BedConfig, camera: &Camera) -> Bed {
        let distance = camera.position.z;
        let variants = growth_rows(seed, config, camera.fx / distance);
        let max_radius = variants.iter().map(|v| v.morphology.cap_radius).fold(0.0, f64::max);
        // Mushrooms centred just outside the frame still reach into it.
        let region = camera.footprint(0.0).grown(max_radius + 0.005);
        let compost = Compost::new(Rng::stream(seed, Stream::Ground).next_u64());
        let instances = place_instances(seed, config, region, &variants, &compost);
        // Lower ground widens the view; 1 cm below the plane covers all the relief.
        let ground_region = camera.footprint(-0.01);
        let ground = compost.mesh(ground_region, GROUND_CELL_PX * camera.pixel_footprint(distance));
        Bed { variants, instances, ground }
    }

    /// World-space vertices of instance `i`.
    pub fn instance_positions(&self, i: usize) -> Vec<Vec3> {
        let instance = &self.instances[i];
        let rotation = instance.rotation();
        self.variants[instance.variant].mesh.positions.iter().map(|&p| instance.to_world(&rotation, p)).collect()
    }
}

/// `rows` individuals (one seed each) grown through `stages` ages, meshed for their size on
/// screen (`pixels_per_metre` at the bed).
fn growth_rows(seed: u64, config: &BedConfig, pixels_per_metre: f64) -> Vec<Variant> {
    let mut rng = Rng::stream(seed, Stream::VariantRows);
    let mut variants = Vec::with_capacity(config.rows * config.stages);
    for row in 0..config.rows {
        let mut params = MushroomParams { age: config.first_age, randomness: config.randomness, seed: rng.next_u64() };
        for stage in 0..config.stages {
            let morphology = params.morphology();
            let mesh = morphology.mesh(Lod::for_cap_pixels(params.cap_diameter() * pixels_per_metre));
            variants.push(Variant { row, stage, params, morphology, mesh });
            params = params.grown(config.age_increment);
        }
    }
    variants
}

fn place_instances(
    seed: u64,
    config: &BedConfig,
    region: Rect,
    variants: &[Variant],
    compost: &Compost,
) -> Vec<Instance> {
    let mut rng = Rng::stream(seed, Stream::Placement);
    let count = (config.density * region.area()).round() as usize;
    let points = clustered_points(&mut rng, region, count, &config.clumping);
    let chosen: Vec<usize> = (0..count).map(|_| rng.below(variants.len() as u64) as usize).collect();
    let proposals: Vec<(f64, f64, f64)> =
        points.iter().zip(&chosen).map(|(&(x, y), &v)| (x, y, variants[v].morphology.cap_radius)).collect();
    let max_tilt = config.max_tilt_deg.to_radians();
    place_disks(&proposals, region)
        .into_iter()
        .map(|p| Instance {
            variant: chosen[p.index],
            base: Vec3::new(p.x, p.y, compost.height(p.x, p.y)),
            yaw: rng.range(0.0, std::f64::consts::TAU),
            tilt: (rng.range(-max_tilt, max_tilt), rng.range(-max_tilt, max_tilt)),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::SceneConfig;

    fn camera() -> Camera {
        SceneConfig::default().camera()
    }

    #[test]
    fn eighty_variants_in_four_rows_of_growth() {
        let bed = Bed::generate(3, &BedConfig::default(), &camera());
        assert_eq!(bed.variants.len(), 80);
        for row in bed.variants.chunks(20) {
            assert!(row.iter().all(|v| v.params.seed == row[0].params.seed && v.params.randomness == 0.25));
            assert!((row[0].params.age - 0.05).abs() < 1e-12 && (row[19].params.age - 1.0).abs() < 1e-9);
            assert!(row.windows(2).all(|w| w[1].morphology.cap_radius > w[0].morphology.cap_radius));
        }
        assert_ne!(bed.variants[0].params.seed, bed.variants[20].params.seed);
    }

    #[test]
    fn instances_use_every_stage_with_bounded_tilt_on_the_ground() {
        let bed = Bed::generate(5, &BedConfig::default(), &camera());
        assert!(bed.instances.len() > 150, "{} instances", bed.instances.len());
        let max_tilt = 10f64.to_radians();
        let compost = Compost::new(Rng::stream(5, Stream::Ground).next_u64());
        for inst in &bed.instances {
            assert!(inst.tilt.0.abs() <= max_tilt && inst.tilt.1.abs() <= max_tilt);
            assert!((0.0..std::f64::consts::TAU).contains(&inst.yaw));
            assert_eq!(inst.base.z, compost.height(inst.base.x, inst.base.y));
        }
        let mut stages = [false; 20];
        bed.instances.iter().for_each(|i| stages[bed.variants[i.variant].stage] = true);
        assert!(stages.iter().all(|&s| s));
    }

    #[test]
    fn placed_mushrooms_keep_the_poisson_distance_of_their_caps() {
        let bed = Bed::generate(6, &BedConfig::default(), &camera());
        let radius = |i: &Instance| bed.variants[i.variant].morphology.cap_radius;
        for (n, a) in bed.instances.iter().enumerate() {
            for b in &bed.instances[n + 1..] {
                let d = (a.base.x - b.base.x).hypot(a.base.y - b.base.y);
                assert!(d >= crate::poisson::min_distance(radius(a), radius(b)), "{a:?} and {b:?}");
            }
        }
    }

    #[test]
    fn density_scales_the_count_and_zero_is_an_empty_bed() {
        let count =
            |density: f64| Bed::generate(8, &BedConfig { density, ..BedConfig::default() }, &camera()).instances.len();
        assert_eq!(count(0.0), 0);
        assert!(count(400.0) < count(800.0));
        assert!(BedConfig { density: -1.0, ..BedConfig::default() }.validate().is_err());
    }
}
