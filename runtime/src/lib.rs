//! vkdiff's Vulkan runtime: device choice, memory, tensors, cached kernel pipelines, command
//! recording with barriers and profiling, and the typed operations networks are built from.

mod arena;
mod context;
mod device;
mod error;
mod memory;
pub mod ops;
mod pipeline;
mod recorder;
mod submit;
mod tensor;
mod validation;

pub use arena::Arena;
pub use context::{gpu_paths_requested, Context, GemmFamily};
pub use device::{choose, list_devices, DeviceInfo, DeviceKind};
pub use error::{Error, Result};
pub use pipeline::Kernel;
pub use recorder::{Recorder, Recording, Timing};
pub use tensor::{dtype_size, Dtype, Tensor};
