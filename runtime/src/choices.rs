//! What a context runs with now: its kernels, limits and submissions. Each starts as the
//! context's [`crate::KernelPlan`] and the device say; tests and benchmarks change them per
//! context with [`crate::Context::choose`] (a test runs both GEMM families on one device, or splits
//! tensors below the device's binding limit).

use crate::device::DeviceInfo;
use crate::kernel_choice::matrix_tile::MatrixTile;
use crate::kernel_choice::plan::{GemmFamily, KernelPlan};
use crate::kernel_choice::probe::ProbeChoice;
use crate::settings::Settings;
use crate::submit_budget::SubmitBudget;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Choices {
    /// The GEMM and convolution kernels.
    pub gemm_family: GemmFamily,
    /// The matrix-unit GEMM and convolution's workgroup tile.
    pub matrix_tile: MatrixTile,
    /// VK_NV_cooperative_matrix2's probe, or the kernel `ops` picks, per op.
    pub attention: ProbeChoice,
    pub linear: ProbeChoice,
    pub conv: ProbeChoice,
    /// Whether the device runs as a discrete GPU would: device-only memory reached through
    /// staging buffers, the GPU GEMM/convolution and attention kernels. On lavapipe this proves
    /// the code a GPU runs. Change it with [`crate::Context::set_gpu_paths`], which takes the kernels
    /// with it.
    pub gpu_paths: bool,
    /// Whether small products take the kernel variants that compile quickly rather than those
    /// that run fastest (8 rows per workgroup for the subgroup GEMM and convolution with fewer
    /// than 2¹⁷ weights or at most 8 rows, the workgroup attention for fewer than 256 channels:
    /// tiny models, whose products take milliseconds).
    pub quick_compile: bool,
    /// Whether the subgroup-register kernels read their operands as 64-bit words (their WD = 1
    /// variants; [`KernelPlan`]'s `word_loads` says where), not as 32-bit words. Tests run both.
    pub word_loads: bool,
    /// Whether the subgroup-register kernels read B, and A of the plain products, through texel
    /// views (their TB = 1 variants; [`KernelPlan`]'s `texel_reads` says where). Tests run both.
    pub texel_reads: bool,
    /// The fewest filter weights from which 3×3 convolutions of stride 1 run as Winograd's
    /// F(2×2, 3×3) (ops/winograd.rs), None for none ([`KernelPlan`]'s `winograd` says where:
    /// every convolution of SDXL's networks but the first and last, none of the tiny test
    /// models', whose scratch would outweigh their activations). Tests run both, and from 0.
    pub winograd_from: Option<usize>,
    /// Where recordings split into submissions and how long a wait for one may last.
    pub submit_budget: SubmitBudget,
    /// The most bytes one kernel binding may span; ops split larger tensors into bands below
    /// it. At most the device's `maxStorageBufferRange`.
    pub binding_limit: u64,
    /// The largest buffer one allocation may hold: at most the device's
    /// `maxMemoryAllocationSize`.
    pub allocation_limit: u64,
    /// The most workgroups one dispatch may have per dimension (larger grids are split): from
    /// 1 to the device's own.
    pub workgroup_limit: [u32; 3],
}

impl Choices {
    /// The choices a context on `info` starts with under `plan` and `settings`.
    pub(crate) fn start(info: &DeviceInfo, plan: &KernelPlan, settings: &Settings) -> Choices {
        let [attention, linear, conv] = plan.probes;
        Choices {
            gemm_family: plan.gemm,
            matrix_tile: plan.tile,
            attention,
            linear,
            conv,
            gpu_paths: plan.gpu_paths,
            quick_compile: plan.quick_compile,
            word_loads: plan.word_loads,
            texel_reads: plan.texel_reads,
            winograd_from: plan.winograd.then_some(crate::ops::SMALL_WEIGHTS),
            submit_budget: SubmitBudget::for_device(info, settings),
            binding_limit: info.max_storage_buffer_range,
            allocation_limit: info.max_allocation,
            workgroup_limit: info.max_workgroup_count,
        }
    }

    /// These choices with the limits no higher than `info`'s own, word loads only where it has
    /// the integers they need, and texel reads only where it fetches texels.
    pub(crate) fn within(mut self, info: &DeviceInfo) -> Choices {
        self.binding_limit = self.binding_limit.min(info.max_storage_buffer_range);
        if info.max_allocation > 0 {
            self.allocation_limit = self.allocation_limit.min(info.max_allocation);
        }
        self.workgroup_limit = [0, 1, 2].map(|i| self.workgroup_limit[i].clamp(1, info.max_workgroup_count[i]));
        self.word_loads &= info.can_read_words();
        self.texel_reads &= info.reads_texels();
        self
    }
}
