//! Which kernels run: decided once per device by [`plan::KernelPlan::for_device`] (the one entry
//! point: the GEMM and convolution family, the matrix units' fragment and tile, attention's
//! kernels, the quickly compiled variants) from what the device reports and the settings; then
//! kept or changed by what runs (the matrix units' trial as a context starts, tuning per shape).
//! The ops read the choices a context holds, never the device or the settings again.

pub(crate) mod census;
pub(crate) mod cpu_vectors;
pub(crate) mod flexible_dimensions;
pub(crate) mod matrix2_tile;
pub(crate) mod matrix_tile;
pub(crate) mod matrix_units;
pub(crate) mod plan;
pub(crate) mod probe;
pub(crate) mod trial;
pub(crate) mod trial_run;
pub(crate) mod tuned;
pub(crate) mod tuning;
