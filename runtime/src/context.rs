//! The device context: logical device, queue, allocator, pipeline cache and memory figures.

use crate::device::{self, DeviceInfo, DeviceKind};
use crate::device_choice::{choose, DeviceChoice};
use crate::error::{Error, Result, VkContext};
use crate::flexible_dimensions::CooperativeMatrix2Features;
use crate::host_stats::HostStats;
use crate::idle_buffers::{cache_setting, IdleBuffers};
use crate::instance::Instance;
use crate::matrix_unit_trial::{run_trial, CooperativeSetting, MatrixUnitTrial};
use crate::matrix_units;
use crate::pipeline::{Kernel, PipelineCache};
use crate::recorder::Timing;
use crate::submit_budget::SubmitBudget;
use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};
use std::collections::HashMap;
use std::mem::ManuallyDrop;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use vkdiff_kernels::Variant;

/// Which family of GEMM/convolution kernels a context uses (see kernels/src/spec.rs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GemmFamily {
    /// One subgroup per workgroup, A shared by shuffles: fast where loads are scalarised (CPUs).
    Subgroup,
    /// Shared-memory tiles: the GPU kernel, and the fallback for shapes `Subgroup` cannot take.
    Tiled,
    /// The device's matrix units (`VK_KHR_cooperative_matrix`) for f16 products; f32 products,
    /// and devices whose units fit no variant, take `Tiled`.
    Cooperative,
}

/// Whether `VKDIFF_GPU_PATHS=1` asks for the discrete-GPU configuration (see [`Context::gpu_paths`]).
pub fn gpu_paths_requested() -> bool {
    std::env::var("VKDIFF_GPU_PATHS").is_ok_and(|v| v == "1")
}

impl DeviceInfo {
    /// The GEMM/convolution family a context on this device starts with: the subgroup-register
    /// kernels on CPU devices with a width they are built for; on GPUs (and on the GPU paths)
    /// the matrix units where a cooperative variant fits them and `VKDIFF_COOPERATIVE=0` does
    /// not turn them off, else the tiled kernels. A context then tries the units before it keeps
    /// them ([`crate::MatrixUnitTrial`]).
    pub fn gemm_family(&self, gpu_paths: bool) -> GemmFamily {
        let cpu = !gpu_paths && self.kind == DeviceKind::Cpu;
        let allowed = CooperativeSetting::from_env().map_or(true, |s| s != CooperativeSetting::Never);
        if cpu && self.gemm_subgroup_width().is_some() {
            GemmFamily::Subgroup
        } else if !cpu && self.cooperative_variant().is_some() && allowed {
            GemmFamily::Cooperative
        } else {
            GemmFamily::Tiled
        }
    }

    /// Whether this device compiles kernels slowly enough to prefer the variants that compile
    /// quickly where a product is small: lavapipe after Mesa 22, whose JIT (at a kernel's first
    /// dispatch, once per kernel: Mesa's shader cache keeps it) took 7× longer than 22.3's on the
    /// subgroup GEMM on Mesa 25 and 2.4× on 26.1 (measured, 8 lanes). `VKDIFF_QUICK_COMPILE=1`
    /// or `0` overrides it. Never on the GPU paths, which run the kernels a GPU runs.
    pub fn quick_compile(&self, gpu_paths: bool) -> bool {
        !gpu_paths
            && match std::env::var("VKDIFF_QUICK_COMPILE").as_deref() {
                Ok("1") => true,
                Ok("0") => false,
                _ => self.lavapipe_mesa.is_some_and(|(major, _)| major > 22),
            }
    }

    /// Whether attention may take the subgroup-register variants: on CPU devices, as the GEMM
    /// (their ~300 floats per lane suit lavapipe, not a GPU's register file); GPUs take
    /// `attention_rows`, or `attention_wg` for heads past it.
    pub fn subgroup_attention(&self, gpu_paths: bool) -> bool {
        !gpu_paths && self.kind == DeviceKind::Cpu
    }
}

pub(crate) struct Shared {
    /// The process's instance (see [`crate::instance`]), which outlives every context.
    pub(crate) vulkan: Arc<Instance>,
    pub(crate) physical_device: vk::PhysicalDevice,
    pub(crate) device: ash::Device,
    pub(crate) queue: Mutex<vk::Queue>,
    pub(crate) queue_family: u32,
    pub(crate) allocator: ManuallyDrop<Mutex<Allocator>>,
    pub(crate) info: DeviceInfo,
    pub(crate) live_bytes: AtomicU64,
    pub(crate) peak_bytes: AtomicU64,
    /// Bytes of tensors in host memory ([`crate::Placement::Host`]).
    pub(crate) host_bytes: AtomicU64,
    pub(crate) pipelines: PipelineCache,
    /// Where kernels' statistics are printed as they are compiled (`VKDIFF_PIPELINE_STATS=1`).
    pub(crate) statistics: Option<ash::khr::pipeline_executable_properties::Device>,
    pub(crate) gemm_family: Mutex<GemmFamily>,
    /// See [`Context::matrix_tile`].
    pub(crate) matrix_tile: Mutex<crate::MatrixTile>,
    /// See [`Context::attention_kernel`].
    pub(crate) attention_kernel: Mutex<crate::ProbeChoice>,
    /// See [`Context::linear_kernel`].
    pub(crate) linear_kernel: Mutex<crate::ProbeChoice>,
    /// See [`Context::conv_kernel`].
    pub(crate) conv_kernel: Mutex<crate::ProbeChoice>,
    /// See [`Context::tuning`].
    pub(crate) tuning: AtomicBool,
    /// What tuning found, by each op's key (see [`crate::kernel_tuning`]).
    pub(crate) tuned: Mutex<HashMap<String, crate::TunedShape>>,
    /// Time spent tuning, in nanoseconds (see [`Context::tuning_summary`]).
    pub(crate) tuning_nanos: AtomicU64,
    pub(crate) binding_limit: AtomicU64,
    /// The largest buffer one allocation may hold (`maxMemoryAllocationSize`).
    pub(crate) allocation_limit: AtomicU64,
    /// The most workgroups one dispatch may have per dimension; larger grids are split.
    pub(crate) workgroup_limit: Mutex<[u32; 3]>,
    /// `VKDIFF_GPU_PATHS=1`: run as a discrete GPU would (see [`Context::gpu_paths`]).
    pub(crate) gpu_paths: AtomicBool,
    /// Whether every recording times its dispatches (see [`Context::set_profiling`]).
    pub(crate) profiling: AtomicBool,
    /// The dispatch times of every timed recording run inside [`Context::profiled`].
    pub(crate) collected: Mutex<Option<Vec<Timing>>>,
    /// See [`Context::quick_compile`].
    pub(crate) quick_compile: AtomicBool,
    /// Told how many kernels a submission compiles (see [`Context::on_compile`]).
    pub(crate) compile_notice: Mutex<Option<CompileNotice>>,
    /// See [`Context::submit_budget`].
    pub(crate) submit_budget: Mutex<SubmitBudget>,
    /// A wait for the device timed out: what it may still run is never freed.
    pub(crate) hung: AtomicBool,
    /// `VKDIFF_MEMORY_BUDGET`: the most device memory live tensors may hold (see
    /// [`Context::memory_room`]).
    pub(crate) memory_budget: Option<u64>,
    /// Whether `VK_EXT_memory_budget` is enabled.
    pub(crate) memory_budget_extension: bool,
    /// What the matrix units' trial found, where one ran (see [`Context::matrix_unit_trial`]).
    pub(crate) trial: Mutex<Option<MatrixUnitTrial>>,
    /// Device buffers no tensor holds, kept for reuse (see [`crate::idle_buffers`]) unless
    /// `VKDIFF_BUFFER_CACHE=0`.
    pub(crate) idle: Mutex<IdleBuffers>,
    pub(crate) keep_idle: bool,
    /// The most device memory live tensors have held at once (never reset).
    pub(crate) most_live: AtomicU64,
    pub(crate) host_stats: Mutex<HostStats>,
}

/// `VKDIFF_FRAGMENT`, where set: a shape vkdiff builds that this device's matrix units take.
fn check_requested_fragment(info: &DeviceInfo) -> Result<()> {
    let Some((m, n, k)) = matrix_units::requested_fragment()? else { return Ok(()) };
    if info.cooperative_variant().is_some() {
        return Ok(());
    }
    let listed: Vec<String> = info.matrix_shapes.iter().map(|s| s.label()).collect();
    let flexible: Vec<String> = info.flexible_shapes.iter().map(|s| s.label()).collect();
    Err(Error::BadSetting(format!(
        "VKDIFF_FRAGMENT={m}x{n}x{k}: `{}` does not take it at a subgroup width vkdiff builds it for (it lists: {}; \
         flexible dimensions: {})",
        info.name,
        if listed.is_empty() { "none".into() } else { listed.join(", ") },
        if flexible.is_empty() { "none".into() } else { flexible.join(", ") }
    )))
}

/// Whether kernels' statistics are asked for (`census`: by [`Context::for_census`]) and the
/// device can report them.
fn capture_statistics(info: &DeviceInfo, census: bool) -> bool {
    info.pipeline_statistics && (census || crate::pipeline_stats::requested())
}

/// Called before a submission whose kernels the driver compiles then, with their number.
pub type CompileNotice = Arc<dyn Fn(usize) + Send + Sync>;

impl Drop for Shared {
    fn drop(&mut self) {
        if self.hung.load(Ordering::SeqCst) {
            return; // the device may still run work on these objects; the process ends anyway
        }
        // SAFETY: every buffer and recording holds an Arc<Shared>, so none is alive any more.
        unsafe {
            let _ = self.device.device_wait_idle();
            crate::memory::release_idle(self);
            self.pipelines.destroy(&self.device);
            ManuallyDrop::drop(&mut self.allocator);
            self.device.destroy_device(None);
        }
    }
}

/// A Vulkan device ready to run kernels. Cheap to clone; all clones share one device.
#[derive(Clone)]
pub struct Context {
    pub(crate) shared: Arc<Shared>,
}

impl Context {
    /// Opens the device `choice` names (or `VKDIFF_DEVICE`, the scheduler's, or the best one;
    /// see [`crate::choose`]).
    pub fn new(choice: &DeviceChoice) -> Result<Context> {
        let vulkan = crate::instance::shared()?;
        let (device, pd, info, queue_family) = Self::open(&vulkan, choice, false)?;
        let tuning = crate::kernel_tuning::tuning_from_env()?;
        let ctx = Self::finish(vulkan, device, pd, info, queue_family, false)?;
        ctx.try_matrix_units();
        // After the trial, whose product is timed as it is.
        ctx.set_tuning(tuning)?;
        Ok(ctx)
    }

    /// A context for [`Context::compile_for_census`]: kernels' statistics captured wherever the
    /// device reports them, and no matrix-unit trial (it runs nothing).
    pub fn for_census(choice: &DeviceChoice) -> Result<Context> {
        let vulkan = crate::instance::shared()?;
        let (device, pd, info, queue_family) = Self::open(&vulkan, choice, true)?;
        Self::finish(vulkan, device, pd, info, queue_family, true)
    }

    fn open(
        vulkan: &Instance,
        choice: &DeviceChoice,
        census: bool,
    ) -> Result<(ash::Device, vk::PhysicalDevice, DeviceInfo, u32)> {
        let (entry, instance, api) = (&vulkan.entry, &vulkan.raw, vulkan.api);
        // SAFETY: valid instance.
        let pds = unsafe { instance.enumerate_physical_devices() }.vk("vkEnumeratePhysicalDevices")?;
        let infos: Vec<DeviceInfo> =
            pds.iter().enumerate().map(|(i, &pd)| device::describe(entry, instance, pd, (i, api))).collect();
        let index = choose(&infos, choice)?;
        let info = infos[index].clone();
        let pd = pds[index];
        let family = info.compute_queue_family.expect("checked by choose");
        check_requested_fragment(&info)?;
        CooperativeSetting::from_env()?;
        // Every feature the kernels' SPIR-V declares, where the device has it.
        let mut f11 = vk::PhysicalDeviceVulkan11Features::default()
            .storage_buffer16_bit_access(info.storage_16bit)
            .uniform_and_storage_buffer16_bit_access(info.storage_16bit);
        let mut f12 = vk::PhysicalDeviceVulkan12Features::default()
            .shader_float16(info.shader_f16)
            .vulkan_memory_model(info.cooperative_features);
        let mut cooperative = vk::PhysicalDeviceCooperativeMatrixFeaturesKHR::default().cooperative_matrix(true);
        let matrix2_tiles = info.matrix2_tiles();
        let mut matrix2 = CooperativeMatrix2Features::enabling(&crate::matrix2_tile::features(&matrix2_tiles));
        let size_control = info.subgroup_size_range.is_some();
        let mut f13 = vk::PhysicalDeviceVulkan13Features::default()
            .subgroup_size_control(size_control)
            .compute_full_subgroups(size_control)
            .shader_zero_initialize_workgroup_memory(info.zero_init_workgroup);
        let mut zero_init = vk::PhysicalDeviceZeroInitializeWorkgroupMemoryFeatures::default()
            .shader_zero_initialize_workgroup_memory(true);
        let mut size_control_extension = vk::PhysicalDeviceSubgroupSizeControlFeatures::default()
            .subgroup_size_control(true)
            .compute_full_subgroups(true);
        let priorities = [1.0f32];
        let queues = [vk::DeviceQueueCreateInfo::default().queue_family_index(family).queue_priorities(&priorities)];
        let mut extensions = Vec::new();
        if device::is_portability_subset(instance, pd) {
            extensions.push(ash::khr::portability_subset::NAME.as_ptr());
        }
        let mut create =
            vk::DeviceCreateInfo::default().queue_create_infos(&queues).push_next(&mut f11).push_next(&mut f12);
        // A 1.2 device takes the extensions of the 1.3 features (and no 1.3 struct).
        if info.api_version >= (1, 3, 0) {
            create = create.push_next(&mut f13);
        }
        if info.zero_init_extension {
            extensions.push(ash::khr::zero_initialize_workgroup_memory::NAME.as_ptr());
            create = create.push_next(&mut zero_init);
        }
        if info.size_control_extension {
            extensions.push(ash::ext::subgroup_size_control::NAME.as_ptr());
            create = create.push_next(&mut size_control_extension);
        }
        if info.cooperative_features {
            extensions.push(ash::khr::cooperative_matrix::NAME.as_ptr());
            create = create.push_next(&mut cooperative);
        }
        if info.cooperative_variant().is_some_and(|f| f.flexible) || !matrix2_tiles.is_empty() {
            extensions.push(CooperativeMatrix2Features::EXTENSION.as_ptr());
            create = create.push_next(&mut matrix2);
        }
        if info.memory_budget {
            extensions.push(ash::ext::memory_budget::NAME.as_ptr());
        }
        let mut executables =
            vk::PhysicalDevicePipelineExecutablePropertiesFeaturesKHR::default().pipeline_executable_info(true);
        if capture_statistics(&info, census) {
            extensions.push(ash::khr::pipeline_executable_properties::NAME.as_ptr());
            create = create.push_next(&mut executables);
        }
        let create = create.enabled_extension_names(&extensions);
        // SAFETY: pd belongs to the instance; the create info outlives the call.
        let device = unsafe { instance.create_device(pd, &create, None) }.vk("vkCreateDevice")?;
        Ok((device, pd, info, family))
    }

    fn finish(
        vulkan: Arc<Instance>,
        device: ash::Device,
        pd: vk::PhysicalDevice,
        info: DeviceInfo,
        family: u32,
        census: bool,
    ) -> Result<Context> {
        // SAFETY: index 0 of a family we created one queue in.
        let queue = unsafe { device.get_device_queue(family, 0) };
        let allocator = Allocator::new(&AllocatorCreateDesc {
            instance: vulkan.raw.clone(),
            device: device.clone(),
            physical_device: pd,
            debug_settings: Default::default(),
            buffer_device_address: false,
            allocation_sizes: Default::default(),
        })
        .map_err(|e| Error::Memory(e.to_string()))?;
        let gpu_paths = gpu_paths_requested();
        let gemm_family = info.gemm_family(gpu_paths);
        let matrix_tile = crate::matrix_tile::for_device(&info, gemm_family)?;
        let attention_kernel = crate::ProbeChoice::attention_from_env()?;
        let linear_kernel = crate::ProbeChoice::linear_from_env()?;
        let conv_kernel = crate::ProbeChoice::conv_from_env()?;
        let env = |name: &str| std::env::var(name).ok();
        let submit_budget = SubmitBudget::for_device(&info, &env)?;
        let memory_budget = crate::memory_budget::budget_override(&env)?;
        let keep_idle = cache_setting(env("VKDIFF_BUFFER_CACHE").as_deref())?;
        let statistics = capture_statistics(&info, census)
            .then(|| ash::khr::pipeline_executable_properties::Device::new(&vulkan.raw, &device));
        if crate::pipeline_stats::requested() && statistics.is_none() {
            eprintln!(
                "VKDIFF_PIPELINE_STATS=1: {} reports no kernel statistics (no VK_KHR_pipeline_executable_properties)",
                info.name
            );
        }
        let shared = Shared {
            vulkan,
            physical_device: pd,
            memory_budget,
            memory_budget_extension: info.memory_budget,
            device,
            queue: Mutex::new(queue),
            queue_family: family,
            allocator: ManuallyDrop::new(Mutex::new(allocator)),
            live_bytes: AtomicU64::new(0),
            peak_bytes: AtomicU64::new(0),
            host_bytes: AtomicU64::new(0),
            pipelines: PipelineCache::default(),
            statistics,
            gemm_family: Mutex::new(gemm_family),
            matrix_tile: Mutex::new(matrix_tile),
            attention_kernel: Mutex::new(attention_kernel),
            linear_kernel: Mutex::new(linear_kernel),
            conv_kernel: Mutex::new(conv_kernel),
            tuning: AtomicBool::new(false),
            tuned: Mutex::new(HashMap::new()),
            tuning_nanos: AtomicU64::new(0),
            binding_limit: AtomicU64::new(info.max_storage_buffer_range),
            allocation_limit: AtomicU64::new(info.max_allocation),
            workgroup_limit: Mutex::new(info.max_workgroup_count),
            gpu_paths: AtomicBool::new(gpu_paths),
            profiling: AtomicBool::new(false),
            collected: Mutex::new(None),
            quick_compile: AtomicBool::new(info.quick_compile(gpu_paths)),
            compile_notice: Mutex::new(None),
            submit_budget: Mutex::new(submit_budget),
            hung: AtomicBool::new(false),
            trial: Mutex::new(None),
            idle: Mutex::new(IdleBuffers::default()),
            keep_idle,
            most_live: AtomicU64::new(0),
            host_stats: Mutex::new(HostStats::default()),
            info,
        };
        Ok(Context { shared: Arc::new(shared) })
    }

    /// Where this context would run products on the matrix units and `VKDIFF_COOPERATIVE` is
    /// unset or `auto`, times one on them and on the tiled kernels and keeps the units only where they
    /// agree and are not clearly slower ([`MatrixUnitTrial::keeps_matrix_units`]); says so
    /// where it drops them. A trial that fails drops them too: the tiled kernels then run alone.
    fn try_matrix_units(&self) {
        if self.gemm_family() != GemmFamily::Cooperative
            || !matches!(CooperativeSetting::from_env(), Ok(CooperativeSetting::Trial))
        {
            return;
        }
        let name = &self.info().name;
        match run_trial(self) {
            Ok(trial) => {
                if !trial.keeps_matrix_units() {
                    eprintln!("vkdiff: {}", trial.summary(name));
                    self.set_gemm_family(GemmFamily::Tiled);
                }
                *self.shared.trial.lock().unwrap() = Some(trial);
            }
            Err(e) => {
                eprintln!("vkdiff: `{name}`: the matrix units' trial failed ({e}): using the tiled kernels");
                self.set_gemm_family(GemmFamily::Tiled);
            }
        }
        // The trial's tensors are gone: their buffers go back to the driver, and the peak and the
        // most ever held (which bounds the idle buffers kept) are the caller's work alone.
        crate::memory::release_idle(&self.shared);
        self.shared.most_live.store(self.live_bytes(), Ordering::SeqCst);
        self.reset_peak();
    }

    /// What the matrix units' trial at this context's start found; `None` where none ran (no
    /// variant fits, a CPU device, or `VKDIFF_COOPERATIVE` set to on or off).
    pub fn matrix_unit_trial(&self) -> Option<MatrixUnitTrial> {
        *self.shared.trial.lock().unwrap()
    }

    pub fn info(&self) -> &DeviceInfo {
        &self.shared.info
    }

    /// The pipeline for `variant`, created on first use and kept for the context's lifetime.
    pub fn kernel(&self, variant: &'static Variant, bindings: u32) -> Result<Arc<Kernel>> {
        let pinned_subgroups = self.shared.info.subgroup_size_range.is_some();
        let statistics = self.shared.statistics.as_ref();
        self.shared.pipelines.kernel(&self.shared.device, (pinned_subgroups, statistics), variant, bindings)
    }

    /// Bytes of device memory held by live tensors now.
    pub fn live_bytes(&self) -> u64 {
        self.shared.live_bytes.load(Ordering::SeqCst)
    }

    /// Bytes of device memory in buffers no tensor holds, kept for reuse.
    pub fn idle_bytes(&self) -> u64 {
        self.shared.idle.lock().unwrap().bytes()
    }

    /// Buffers allocated fresh and reused so far, and the host's time allocating and recording.
    pub fn host_stats(&self) -> HostStats {
        *self.shared.host_stats.lock().unwrap()
    }

    /// The most device memory held at once since the context opened or [`Context::reset_peak`].
    pub fn peak_bytes(&self) -> u64 {
        self.shared.peak_bytes.load(Ordering::SeqCst)
    }

    /// Bytes of host memory held by live tensors placed there ([`crate::Placement::Host`]).
    pub fn host_bytes(&self) -> u64 {
        self.shared.host_bytes.load(Ordering::SeqCst)
    }

    pub fn reset_peak(&self) {
        self.shared.peak_bytes.store(self.live_bytes(), Ordering::SeqCst);
    }
}
