//! vkdiff's command-line flags as clap types, shared by the commands (the `vkdiff` binary) and
//! the benchmarks (`vkdiff-bench`): the model with its guides and LoRAs, how images are sampled,
//! the precision, and the scene and its crops. Parsing only: each turns into the libraries'
//! settings, which check themselves.

mod device;
mod flags;
mod hub;
mod model;
mod progress;
mod scene;
mod usage;

pub use device::DeviceArgs;
pub use flags::{dataset_flag, flag};
pub use hub::{hub_cache, resolve_in, resolve_model, Resolved, Wants};
pub use model::{parse_lora, ModelArgs, Precision, SamplingArgs};
pub use progress::Progress;
pub use scene::{ControlMode, CropArgs, SceneSettings};
pub use usage::{ensure_usage, Usage};
