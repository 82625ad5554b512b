//! vkdiff-render: procedural white button mushroom beds and a CPU rasterizer that turns them into
//! training annotations (metric depth, instance masks, COCO), with no GPU anywhere.
//!
//! The pipeline, one module per step:
//! - the scene: [`mushroom`] (one *Agaricus bisporus* from age, randomness, seed) revolved into a
//!   [`mesh`]; [`bed`] (80 growth-stage variants, placed by [`poisson`] on the [`ground`] made
//!   from [`noise`]), all seen by the [`camera`] — gathered in [`scene`];
//! - the picture: [`raster`] (z-buffer: planar depth and an id per pixel), [`frame`] (ids
//!   renumbered 1..K over the visible mushrooms), [`crops`];
//! - the files: [`exr`] (depth.exr), [`png_out`] (instances.png, control.png, preview.png from
//!   [`control`] and [`preview`]), [`coco`] with [`rle`] (annotations.json), written atomically by
//!   [`output`] through [`staging`];
//! - [`bench`](mod@bench) times the stages. Randomness comes from [`rng`] only, seeded per scene and per
//!   stream, so the bytes depend on the seed and the settings, never on threads.

pub mod bed;
pub mod bench;
pub mod camera;
pub mod coco;
pub mod control;
pub mod crops;
pub mod error;
pub mod exr;
pub mod frame;
pub mod geometry;
pub mod ground;
pub mod math;
pub mod mesh;
pub mod mushroom;
pub mod noise;
pub mod output;
pub mod png_out;
pub mod poisson;
pub mod preview;
pub mod raster;
pub mod rle;
pub mod rng;
pub mod scene;
pub mod staging;

pub use error::{RenderError, Result};

/// Runs `work` on a pool of `threads` workers (0: one per core). Outputs never depend on the
/// count; it only sets how many cores the work may use.
pub fn with_threads<R: Send>(
    threads: usize,
    work: impl FnOnce() -> R + Send,
) -> std::result::Result<R, rayon::ThreadPoolBuildError> {
    Ok(rayon::ThreadPoolBuilder::new().num_threads(threads).build()?.install(work))
}
