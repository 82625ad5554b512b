//! vkdiff-render: procedural white button mushroom beds and a CPU rasterizer that turns them into
//! training annotations (metric depth, instance masks, COCO), with no GPU anywhere.

pub mod bed;
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
pub mod png_out;
pub mod poisson;
pub mod preview;
pub mod raster;
pub mod rle;
pub mod rng;
pub mod scene;
pub mod staging;

pub use error::{RenderError, Result};
