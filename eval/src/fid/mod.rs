//! Fréchet and kernel Inception distances between two sets of feature rows, as torch-fidelity
//! computes them.

mod cache;
mod features;
mod job;
pub mod numpy_rng;
pub mod stats;

pub use cache::FeatureCache;
pub use features::{check_images, file_stamp, list_images, open_weights, FeatureExtractor};
pub use job::{user_cache_base, CacheDir, FidJob, FidOutcome, FidRequest, FolderFeatures};
pub use stats::{fid, kid, Kid, KidOptions};
