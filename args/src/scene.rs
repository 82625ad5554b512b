//! The scene flags `scene`, `dataset` and `bench scene` share: the bed, the crops, and how depth
//! becomes a control image.

use clap::{Args, ValueEnum};
use vkdiff_render::bed::BedConfig;
use vkdiff_render::control::ControlDepth;
use vkdiff_render::scene::SceneConfig;

/// Settings shared by `scene` and `bench scene`.
#[derive(Args, Debug)]
pub struct SceneSettings {
    /// Seed of the (first) scene (`dataset`: also of every image's seed); the same seed and settings
    /// give byte-identical files.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Frame width in pixels (the camera's 1920×1080 by default).
    #[arg(long, default_value_t = 1920)]
    width: u32,
    /// Frame height in pixels.
    #[arg(long, default_value_t = 1080)]
    height: u32,
    /// Mushrooms proposed per m² of bed (the default gives about 145 visible per 1920×1080 frame).
    #[arg(long, default_value_t = BedConfig::default().density, allow_negative_numbers = true)]
    density: f64,
    /// Share of mushrooms growing in clumps, 0 (spread evenly) to 1.
    #[arg(long, default_value_t = BedConfig::default().clumping.clustered_fraction, allow_negative_numbers = true)]
    clumping: f64,
    /// Worker threads (0: one per core). Output does not depend on it.
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
}

impl SceneSettings {
    pub fn config(&self) -> SceneConfig {
        let mut bed = BedConfig { density: self.density, ..BedConfig::default() };
        bed.clumping.clustered_fraction = self.clumping;
        SceneConfig { width: self.width, height: self.height, bed, ..SceneConfig::default() }
    }
}

/// How each frame is cut into square crops; shared by `scene` and `dataset`.
#[derive(Args, Debug)]
pub struct CropArgs {
    /// Square crops per scene (`scene`: under DIR/crops/<k>/; `dataset`: one image each, and 0
    /// makes one image of the whole frame, cut centred to the sides the model makes, e.g.
    /// 1920×1080 → 1920×1056 for SDXL's multiples of 32).
    #[arg(long, default_value_t = 0)]
    pub crops: usize,
    /// The crops' side in pixels (SDXL's 1024 by default; with a model, a multiple of 32).
    #[arg(long, default_value_t = 1024)]
    pub crop_size: u32,
    /// Drop an instance from a crop when less than this share of its visible pixels falls inside.
    #[arg(long, default_value_t = 0.1, allow_negative_numbers = true)]
    pub crop_min_fraction: f64,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum ControlMode {
    /// Per-image min–max of 1/z (as MiDaS-style depth estimators give), near = bright.
    Inverse,
    /// Per-image min–max of z, reversed so near = bright.
    Linear,
}

impl From<ControlMode> for ControlDepth {
    fn from(mode: ControlMode) -> ControlDepth {
        match mode {
            ControlMode::Inverse => ControlDepth::Inverse,
            ControlMode::Linear => ControlDepth::Linear,
        }
    }
}
