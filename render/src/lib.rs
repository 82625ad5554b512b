//! vkdiff-render: procedural white button mushroom beds and a CPU rasterizer that turns them into
//! training annotations (metric depth, instance masks, COCO), with no GPU anywhere.

pub mod bed;
pub mod bench;
pub mod camera;
pub mod coco;
pub mod control;
pub mod crops;
pub mod error;
pub mod exr;
pub mod frame;
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
pub fn with_threads<R: Send>(threads: usize, work: impl FnOnce() -> R + Send) -> std::result::Result<R, rayon::ThreadPoolBuildError> {
    Ok(rayon::ThreadPoolBuilder::new().num_threads(threads).build()?.install(work))
}
