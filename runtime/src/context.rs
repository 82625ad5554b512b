//! The device context: logical device, queue, allocator, pipeline cache and memory figures.

use crate::choices::Choices;
use crate::device::{self, searched_drivers, DeviceInfo, DeviceKind};
use crate::device_choice::{choose, DeviceChoice};
use crate::error::{Error, Result, VkContext};
use crate::host_stats::HostStats;
use crate::idle_buffers::IdleBuffers;
use crate::instance::Instance;
use crate::kernel_choice::flexible_dimensions::CooperativeMatrix2Features;
use crate::kernel_choice::plan::KernelPlan;
use crate::kernel_choice::trial::MatrixUnitTrial;
use crate::pipeline::{Kernel, PipelineCache};
use crate::settings::Settings;
use crate::timing::Timing;
use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};
use std::collections::HashMap;
use std::mem::ManuallyDrop;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use vkdiff_kernels::Variant;

impl DeviceInfo {
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
    /// The settings the context was opened with, and the kernels they and the device chose.
    pub(crate) settings: Settings,
    pub(crate) plan: KernelPlan,
    /// See [`Context::choices`].
    pub(crate) choices: Mutex<Choices>,
    /// See [`Context::tuning`].
    pub(crate) tuning: AtomicBool,
    /// What tuning found, by each op's key (see [`crate::kernel_choice::tuning`]).
    pub(crate) tuned: Mutex<HashMap<String, crate::kernel_choice::tuned::TunedShape>>,
    /// Time spent tuning, in nanoseconds (see [`Context::tuning_summary`]).
    pub(crate) tuning_nanos: AtomicU64,
    /// Whether every recording times its dispatches (see [`Context::set_profiling`]).
    pub(crate) profiling: AtomicBool,
    /// The dispatch times of every timed recording run inside [`Context::profiled`].
    pub(crate) collected: Mutex<Option<Vec<Timing>>>,
    /// Told how many kernels a submission compiles (see [`Context::on_compile`]).
    pub(crate) compile_notice: Mutex<Option<CompileNotice>>,
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
fn check_requested_fragment(info: &DeviceInfo, requested: Option<(u32, u32, u32)>) -> Result<()> {
    let Some((m, n, k)) = requested else { return Ok(()) };
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

/// Whether kernels' statistics are asked for (`census`: by [`Context::for_census`]; or
/// `VKDIFF_PIPELINE_STATS`) and the device can report them.
fn capture_statistics(info: &DeviceInfo, census: bool, settings: &Settings) -> bool {
    info.pipeline_statistics && (census || settings.pipeline_stats)
}

/// Called before a submission whose kernels the driver compiles then, with their number.
pub type CompileNotice = Arc<dyn Fn(usize) + Send + Sync>;

/// A Vulkan device ready to run kernels. Cheap to clone; all clones share one device.
#[derive(Clone)]
pub struct Context {
    pub(crate) shared: Arc<Shared>,
}

impl Context {
    /// A context for [`Context::compile_for_census`]: kernels' statistics captured wherever the
    /// device reports them, and no matrix-unit trial (it runs nothing).
    pub fn for_census(choice: &DeviceChoice, settings: Settings) -> Result<Context> {
        Self::open(choice, settings, true)
    }

    pub(crate) fn open(choice: &DeviceChoice, settings: Settings, census: bool) -> Result<Context> {
        let vulkan = crate::instance::shared(&settings, &|| searched_drivers(&choice.environment))?;
        let (device, pd, info, queue_family) = Self::create_device(&vulkan, choice, &settings, census)?;
        Self::finish(vulkan, device, pd, (info, queue_family), settings, census)
    }

    fn create_device(
        vulkan: &Instance,
        choice: &DeviceChoice,
        settings: &Settings,
        census: bool,
    ) -> Result<(ash::Device, vk::PhysicalDevice, DeviceInfo, u32)> {
        let (entry, instance, api) = (&vulkan.entry, &vulkan.raw, vulkan.api);
        // SAFETY: valid instance.
        let pds = unsafe { instance.enumerate_physical_devices() }.vk("vkEnumeratePhysicalDevices")?;
        let infos: Vec<DeviceInfo> = pds
            .iter()
            .enumerate()
            .map(|(i, &pd)| device::describe(entry, instance, pd, (i, api), settings.fragment))
            .collect();
        let index = choose(&infos, choice)?;
        let info = infos[index].clone();
        let pd = pds[index];
        let family = info.compute_queue_family.expect("checked by choose");
        check_requested_fragment(&info, settings.fragment)?;
        // Every feature the kernels' SPIR-V declares, where the device has it.
        let mut f11 = vk::PhysicalDeviceVulkan11Features::default()
            .storage_buffer16_bit_access(info.storage_16bit)
            .uniform_and_storage_buffer16_bit_access(info.storage_16bit);
        let mut f12 = vk::PhysicalDeviceVulkan12Features::default()
            .shader_float16(info.shader_f16)
            .vulkan_memory_model(info.cooperative_features);
        let mut cooperative = vk::PhysicalDeviceCooperativeMatrixFeaturesKHR::default().cooperative_matrix(true);
        let matrix2_tiles = info.matrix2_tiles();
        let mut matrix2 =
            CooperativeMatrix2Features::enabling(&crate::kernel_choice::matrix2_tile::features(&matrix2_tiles));
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
        let core = vk::PhysicalDeviceFeatures::default().shader_int64(info.shader_int64);
        let mut create = vk::DeviceCreateInfo::default()
            .queue_create_infos(&queues)
            .enabled_features(&core)
            .push_next(&mut f11)
            .push_next(&mut f12);
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
        if capture_statistics(&info, census, settings) {
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
        (info, family): (DeviceInfo, u32),
        settings: Settings,
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
        let plan = KernelPlan::for_device(&info, &settings);
        if let Some(note) = &plan.tile_note {
            eprintln!("vkdiff: {note}");
        }
        let statistics = capture_statistics(&info, census, &settings)
            .then(|| ash::khr::pipeline_executable_properties::Device::new(&vulkan.raw, &device));
        if settings.pipeline_stats && statistics.is_none() {
            eprintln!(
                "VKDIFF_PIPELINE_STATS=1: {} reports no kernel statistics (no VK_KHR_pipeline_executable_properties)",
                info.name
            );
        }
        let shared = Shared {
            vulkan,
            physical_device: pd,
            memory_budget: settings.memory_budget,
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
            choices: Mutex::new(Choices::start(&info, &plan, &settings)),
            settings,
            plan,
            tuning: AtomicBool::new(false),
            tuned: Mutex::new(HashMap::new()),
            tuning_nanos: AtomicU64::new(0),
            profiling: AtomicBool::new(false),
            collected: Mutex::new(None),
            compile_notice: Mutex::new(None),
            hung: AtomicBool::new(false),
            trial: Mutex::new(None),
            idle: Mutex::new(IdleBuffers::default()),
            keep_idle: settings.buffer_cache,
            most_live: AtomicU64::new(0),
            host_stats: Mutex::new(HostStats::default()),
            info,
        };
        Ok(Context { shared: Arc::new(shared) })
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
        self.shared.pipelines.kernel(&self.shared.device, self.compile_options(), variant, bindings)
    }

    /// How this device's pipelines are created: subgroup sizes pinned where it can, constant-lane
    /// shuffles as broadcasts where it builds shuffles as loops, and statistics where asked for
    /// (`pipeline::create_kernel`).
    pub(crate) fn compile_options(&self) -> (bool, bool, Option<&ash::khr::pipeline_executable_properties::Device>) {
        let info = &self.shared.info;
        (info.subgroup_size_range.is_some(), info.shuffles_loop_over_lanes(), self.shared.statistics.as_ref())
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

    /// Sets what to call before a submission on a device that compiles its kernels at their
    /// first dispatch (lavapipe) when kernels that never ran in this process are in it: the
    /// first runs on a cold Mesa shader cache can take minutes, so say what the wait is.
    pub fn on_compile(&self, notice: CompileNotice) {
        *self.shared.compile_notice.lock().unwrap() = Some(notice);
    }

    /// Whether this device can pin a kernel to a subgroup of `size` lanes.
    pub(crate) fn subgroup_ok(&self, size: u32) -> bool {
        self.shared.info.can_use_subgroup(size)
    }
}
