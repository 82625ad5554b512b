//! vkdiff's Vulkan runtime: device choice, memory, tensors, cached kernel pipelines, command
//! recording with barriers and profiling, and the typed operations networks are built from.

mod arena;
mod context;
mod cpu_vectors;
mod device;
mod device_choice;
mod error;
mod flexible_dimensions;
mod host_stats;
mod idle_buffers;
mod instance;
mod kernel_census;
mod matrix_unit_trial;
mod matrix_units;
mod memory;
mod memory_budget;
pub mod ops;
mod pipeline;
mod pipeline_stats;
mod recorder;
mod submit;
mod submit_budget;
mod tensor;
mod validation;

pub use arena::Arena;
pub use context::{gpu_paths_requested, CompileNotice, Context, GemmFamily};
pub use cpu_vectors::wider_lavapipe_vectors_available;
pub use device::{api_limit, list_devices, DeviceInfo, DeviceKind};
pub use device_choice::{choose, loader_icds, DeviceChoice, DeviceSpec, PciAddress};
pub use error::{Error, Result};
pub use flexible_dimensions::FEATURE_NAMES as COOPERATIVE_MATRIX2_FEATURES;
pub use host_stats::HostStats;
pub use kernel_census::{selectable_variants, CompiledKernel};
pub use matrix_unit_trial::{run_trial, run_trial_timed_by, CooperativeSetting, MatrixUnitTrial, TrialClock};
pub use matrix_units::{built_cooperative_variants, requested_fragment, Fragment, MatrixShape};
pub use memory::Placement;
pub use memory_budget::{MemoryRoom, HOST_MEMORY};
pub use pipeline::Kernel;
pub use pipeline_stats::{describe as describe_statistics, variant_label, StatisticValue, Statistics};
pub use recorder::{Recorder, Recording, Timing};
pub use submit::device_hung;
pub use submit_budget::{SubmitBudget, DEFAULT_SUBMIT_GFLOP, DISPATCHES_PER_SUBMIT};
pub use tensor::{dtype_size, uniform_values, Dtype, Tensor};
pub use vkdiff_kernels::Variant;
