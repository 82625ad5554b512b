//! One scene from a seed: the camera, the bed, and the passes that turn them into a labelled
//! frame. Each pass is its own function so the benchmark can time it.

use rayon::prelude::*;

use crate::bed::{Bed, BedConfig};
use crate::camera::Camera;
use crate::error::{RenderError, Result};
use crate::frame::Frame;
use crate::math::Vec3;
use crate::raster::{project_mesh, rasterize, ScreenTriangle};

/// Raster id of the compost: the same as "nothing drawn", since both are background.
pub const GROUND_ID: u16 = 0;

#[derive(Clone, Debug, PartialEq)]
pub struct SceneConfig {
    pub width: u32,
    pub height: u32,
    pub lens_mm: f64,
    pub sensor_width_mm: f64,
    /// Height of the camera above the ground plane.
    pub camera_height_m: f64,
    pub bed: BedConfig,
}

impl Default for SceneConfig {
    fn default() -> Self {
        SceneConfig {
            width: 1920,
            height: 1080,
            lens_mm: 50.0,
            sensor_width_mm: 36.0,
            camera_height_m: 1.0,
            bed: BedConfig::default(),
        }
    }
}

/// Largest image side accepted: keeps fixed-point coordinates and buffers far from any limit.
pub const MAX_SIDE: u32 = 16384;

impl SceneConfig {
    pub fn validate(&self) -> Result<()> {
        for (setting, value) in [("width", self.width), ("height", self.height)] {
            if !(16..=MAX_SIDE).contains(&value) {
                return Err(RenderError::invalid(setting, value, format!("must lie in [16, {MAX_SIDE}] pixels")));
            }
        }
        self.bed.validate()
    }

    pub fn camera(&self) -> Camera {
        let position = Vec3::new(0.0, 0.0, self.camera_height_m);
        Camera::top_down(self.width, self.height, self.lens_mm, self.sensor_width_mm, position)
    }
}

#[derive(Clone, Debug)]
pub struct Scene {
    pub camera: Camera,
    pub bed: Bed,
}

impl Scene {
    /// The scene of `seed`; fails only when the bed holds more mushrooms than 16-bit ids.
    pub fn build(seed: u64, config: &SceneConfig) -> Result<Scene> {
        let camera = config.camera();
        let bed = Bed::generate(seed, &config.bed, &camera);
        if bed.instances.len() >= u16::MAX as usize {
            return Err(RenderError::TooManyInstances { count: bed.instances.len() });
        }
        Ok(Scene { camera, bed })
    }

    /// Screen triangles of the ground, then of every mushroom in bed order (raster id = bed
    /// index + 1), as lists whose concatenation is the drawing order.
    pub fn project(&self) -> Vec<Vec<ScreenTriangle>> {
        let mut lists = project_mesh(&self.camera, &self.bed.ground.positions, &self.bed.ground.triangles, GROUND_ID);
        let mushrooms: Vec<Vec<ScreenTriangle>> = (0..self.bed.instances.len())
            .into_par_iter()
            .flat_map_iter(|i| {
                let mesh = &self.bed.variants[self.bed.instances[i].variant].mesh;
                project_mesh(&self.camera, &self.bed.instance_positions(i), &mesh.triangles, i as u16 + 1)
            })
            .collect();
        lists.extend(mushrooms);
        lists
    }

    /// The whole pipeline: project, rasterize, label.
    pub fn render(&self) -> Frame {
        let raster = rasterize(self.camera.width, self.camera.height, &self.project());
        Frame::from_raster(raster, &self.camera, &self.bed)
    }
}
