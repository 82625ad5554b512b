//! torch-fidelity's InceptionV3 feature extractor (FID's 2048 pool features), and random
//! weights of its architecture for benchmarks.

mod architecture;
mod inception_v3;
mod random;

pub use inception_v3::{InceptionV3, RgbPixels, TensorSource, INCEPTION_FEATURES, INCEPTION_SIZE};
pub use random::RandomInception;
