//! A context's settings: the kernel families and tiles it takes, its limits, whether it runs the
//! GPU paths and times its dispatches, and how recordings are submitted. Each starts as the
//! device and the environment say, and tests and benchmarks override them per context.

use crate::context::{CompileNotice, Context, GemmFamily};
use crate::recorder::Timing;
use crate::submit_budget::SubmitBudget;
use std::sync::atomic::Ordering;

impl Context {
    pub fn gemm_family(&self) -> GemmFamily {
        *self.shared.gemm_family.lock().unwrap()
    }

    /// Overrides the per-device choice of GEMM kernels (benchmarks and tests run both).
    pub fn set_gemm_family(&self, family: GemmFamily) {
        *self.shared.gemm_family.lock().unwrap() = family;
    }

    /// The matrix-unit GEMM and convolution's workgroup tile: `VKDIFF_MATRIX_TILE`, or what
    /// [`Context::set_matrix_tile`] set.
    pub fn matrix_tile(&self) -> crate::MatrixTile {
        *self.shared.matrix_tile.lock().unwrap()
    }

    pub fn set_matrix_tile(&self, tile: crate::MatrixTile) {
        *self.shared.matrix_tile.lock().unwrap() = tile;
    }

    /// The attention kernel where the context has a choice: `VKDIFF_ATTENTION`, or what
    /// [`Context::set_attention_kernel`] set.
    pub fn attention_kernel(&self) -> crate::ProbeChoice {
        *self.shared.attention_kernel.lock().unwrap()
    }

    pub fn set_attention_kernel(&self, kernel: crate::ProbeChoice) {
        *self.shared.attention_kernel.lock().unwrap() = kernel;
    }

    /// The linear layers' product kernel where the context has a choice: `VKDIFF_LINEAR`, or what
    /// [`Context::set_linear_kernel`] set.
    pub fn linear_kernel(&self) -> crate::ProbeChoice {
        *self.shared.linear_kernel.lock().unwrap()
    }

    pub fn set_linear_kernel(&self, kernel: crate::ProbeChoice) {
        *self.shared.linear_kernel.lock().unwrap() = kernel;
    }

    /// The convolution kernel where the context has a choice: `VKDIFF_CONV`, or what
    /// [`Context::set_conv_kernel`] set.
    pub fn conv_kernel(&self) -> crate::ProbeChoice {
        *self.shared.conv_kernel.lock().unwrap()
    }

    pub fn set_conv_kernel(&self, kernel: crate::ProbeChoice) {
        *self.shared.conv_kernel.lock().unwrap() = kernel;
    }

    /// The most bytes one kernel binding may span; ops split larger tensors into bands below it.
    pub fn binding_limit(&self) -> u64 {
        self.shared.binding_limit.load(Ordering::SeqCst)
    }

    /// Lowers the binding limit below the device's own (tests exercise the splitting paths with
    /// small tensors); values above the device limit are clamped to it.
    pub fn set_binding_limit(&self, bytes: u64) {
        self.shared.binding_limit.store(bytes.min(self.shared.info.max_storage_buffer_range), Ordering::SeqCst);
    }

    /// Lowers the largest allocation below the device's `maxMemoryAllocationSize` (tests
    /// exercise the refusal with small tensors); values above the device's are clamped to it.
    pub fn set_allocation_limit(&self, bytes: u64) {
        let device = self.shared.info.max_allocation;
        let bytes = if device > 0 { bytes.min(device) } else { bytes };
        self.shared.allocation_limit.store(bytes, Ordering::SeqCst);
    }

    /// Whether `VKDIFF_GPU_PATHS=1` runs this device as a discrete GPU would: device-only memory
    /// reached through staging buffers, the GPU GEMM/convolution kernels (on the matrix units
    /// where they fit, else tiled) and the GPU attention kernels. On lavapipe this proves the
    /// code a GPU runs.
    pub fn gpu_paths(&self) -> bool {
        self.shared.gpu_paths.load(Ordering::SeqCst)
    }

    /// Turns the GPU paths on or off for this context (tests run both on one device); turning
    /// them on also selects the GEMM family a GPU would take (cooperative where it fits, else
    /// tiled) and, as on a GPU, the kernels that run fastest whatever their compile time.
    pub fn set_gpu_paths(&self, on: bool) {
        self.shared.gpu_paths.store(on, Ordering::SeqCst);
        if on {
            self.set_gemm_family(self.shared.info.gemm_family(true));
            self.set_quick_compile(self.shared.info.quick_compile(true));
        }
    }

    /// Makes every recording started from now on time its dispatches, so a network's
    /// recording can be profiled without threading a flag through its layers.
    pub fn set_profiling(&self, on: bool) {
        self.shared.profiling.store(on, Ordering::SeqCst);
    }

    pub(crate) fn profiling(&self) -> bool {
        self.shared.profiling.load(Ordering::SeqCst)
    }

    /// Runs `f` with every recording it makes timing its dispatches, and returns what `f` returns
    /// with the device time of each dispatch its runs made, in order: a whole network call
    /// (a VAE decode, tiles and all) profiled without a handle on its recordings.
    pub fn profiled<T>(&self, f: impl FnOnce() -> T) -> (T, Vec<Timing>) {
        *self.shared.collected.lock().unwrap() = Some(Vec::new());
        self.set_profiling(true);
        let out = f();
        self.set_profiling(false);
        (out, self.shared.collected.lock().unwrap().take().unwrap_or_default())
    }

    /// Whether small products take the kernel variants that compile quickly rather than those
    /// that run fastest (8 rows per workgroup for the subgroup GEMM and convolution with fewer
    /// than 2¹⁷ weights or at most 8 rows, the workgroup attention for fewer than 256 channels:
    /// tiny models, whose products take milliseconds); starts as [`DeviceInfo::quick_compile`].
    pub fn quick_compile(&self) -> bool {
        self.shared.quick_compile.load(Ordering::SeqCst)
    }

    /// Overrides [`Context::quick_compile`] (tests run both).
    pub fn set_quick_compile(&self, on: bool) {
        self.shared.quick_compile.store(on, Ordering::SeqCst);
    }

    /// Sets what to call before a submission on a device that compiles its kernels at their
    /// first dispatch (lavapipe) when kernels that never ran in this process are in it: the
    /// first runs on a cold Mesa shader cache can take minutes, so say what the wait is.
    pub fn on_compile(&self, notice: CompileNotice) {
        *self.shared.compile_notice.lock().unwrap() = Some(notice);
    }

    /// Where recordings split into submissions and how long a wait for one may last (see
    /// [`SubmitBudget`]).
    pub fn submit_budget(&self) -> SubmitBudget {
        *self.shared.submit_budget.lock().unwrap()
    }

    /// Sets the submission budget for recordings started from now on (tests split recordings
    /// at every dispatch, benchmarks measure what splitting costs).
    pub fn set_submit_budget(&self, budget: SubmitBudget) {
        *self.shared.submit_budget.lock().unwrap() = budget;
    }

    /// The most workgroups one dispatch may have per dimension.
    pub fn workgroup_limit(&self) -> [u32; 3] {
        *self.shared.workgroup_limit.lock().unwrap()
    }

    /// Lowers the per-dispatch workgroup limit below the device's own (tests exercise the
    /// splitting of large grids); values above the device limit are clamped to it.
    pub fn set_workgroup_limit(&self, limit: [u32; 3]) {
        let device = self.shared.info.max_workgroup_count;
        *self.shared.workgroup_limit.lock().unwrap() = [0, 1, 2].map(|i| limit[i].clamp(1, device[i]));
    }

    /// Whether this device can pin a kernel to a subgroup of `size` lanes.
    pub(crate) fn subgroup_ok(&self, size: u32) -> bool {
        self.shared.info.can_use_subgroup(size)
    }
}
