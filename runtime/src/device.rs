//! Physical-device discovery: what each Vulkan device offers vkdiff (`DeviceInfo`).

use crate::error::{Result, VkContext};
use crate::kernel_choice::flexible_dimensions::{self, CooperativeMatrix2Features};
use crate::kernel_choice::matrix_units::{self, Fragment, MatrixShape};
use crate::pci::PciAddress;
use crate::settings::Settings;
use crate::texel_views::TexelLimits;
use ash::vk;
use std::ffi::CStr;
use vkdiff_setting::Environment;

/// What kind of device this is, in the order vkdiff prefers them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum DeviceKind {
    Discrete,
    Integrated,
    Virtual,
    Cpu,
    Other,
}

impl DeviceKind {
    fn from_vk(t: vk::PhysicalDeviceType) -> DeviceKind {
        match t {
            vk::PhysicalDeviceType::DISCRETE_GPU => DeviceKind::Discrete,
            vk::PhysicalDeviceType::INTEGRATED_GPU => DeviceKind::Integrated,
            vk::PhysicalDeviceType::VIRTUAL_GPU => DeviceKind::Virtual,
            vk::PhysicalDeviceType::CPU => DeviceKind::Cpu,
            _ => DeviceKind::Other,
        }
    }

    pub fn label(self) -> &'static str {
        match self {
            DeviceKind::Discrete => "discrete GPU",
            DeviceKind::Integrated => "integrated GPU",
            DeviceKind::Virtual => "virtual GPU",
            DeviceKind::Cpu => "CPU",
            DeviceKind::Other => "other",
        }
    }
}

/// Everything vkdiff records about a physical device to choose kernels and report on it.
#[derive(Clone, Debug)]
pub struct DeviceInfo {
    pub index: usize,
    pub name: String,
    pub kind: DeviceKind,
    pub vendor_id: u32,
    pub driver: String,
    /// Mesa's lavapipe, and its Mesa version (major, minor): its JIT compile time and speed per
    /// kernel shape differ between releases.
    pub lavapipe_mesa: Option<(u32, u32)>,
    pub api_version: (u32, u32, u32),
    pub shader_f16: bool,
    /// `shaderInt64`: the CPU family's kernels read 64-bit words at up to 8 lanes.
    pub shader_int64: bool,
    /// 16-bit values in storage buffers: `storageBuffer16BitAccess` and
    /// `uniformAndStorageBuffer16BitAccess` (naga declares the second capability for them).
    pub storage_16bit: bool,
    /// `shaderZeroInitializeWorkgroupMemory` (core in 1.3, else its KHR extension): the kernels
    /// zero their workgroup memory natively (naga's polyfill is seconds of JIT on lavapipe).
    pub zero_init_workgroup: bool,
    /// Whether `zero_init_workgroup` comes from the extension, which must then be enabled.
    pub zero_init_extension: bool,
    /// Whether `subgroup_size_range` comes from `VK_EXT_subgroup_size_control` (a 1.2 device),
    /// which must then be enabled.
    pub size_control_extension: bool,
    pub subgroup_size: u32,
    pub subgroup_size_range: Option<(u32, u32)>,
    pub subgroup_shuffle: bool,
    pub subgroup_arithmetic: bool,
    /// The product shapes `VK_KHR_cooperative_matrix` lists (empty without it).
    pub matrix_shapes: Vec<MatrixShape>,
    /// With `VK_NV_cooperative_matrix2`'s `cooperativeMatrixFlexibleDimensions`: the granularities
    /// (as m, n, k) of the other shapes the units take (empty without it).
    pub flexible_shapes: Vec<MatrixShape>,
    /// The `VK_NV_cooperative_matrix2` features the device reports (by
    /// [`crate::COOPERATIVE_MATRIX2_FEATURES`]' names); empty without the extension.
    pub cooperative_matrix2: Vec<&'static str>,
    /// The fragment shape `VKDIFF_FRAGMENT` asks for (None where unset or malformed: a context
    /// refuses the latter), read once here rather than at every product recorded.
    pub fragment_request: Option<(u32, u32, u32)>,
    /// Whether the cooperative kernels can run: the extension with its `cooperativeMatrix`
    /// feature, and `vulkanMemoryModel` (naga's cooperative SPIR-V declares the Vulkan model).
    pub cooperative_features: bool,
    pub max_storage_buffer_range: u64,
    pub max_shared_memory: u32,
    pub max_workgroup_invocations: u32,
    pub max_workgroup_count: [u32; 3],
    pub max_push_constants: u32,
    pub max_allocation: u64,
    pub device_local_bytes: u64,
    pub min_storage_offset_alignment: u64,
    /// Four-value texels (RGBA in f32 and in f16) read from uniform texel buffers: the texels a
    /// buffer view may hold and the alignment of its offset, where the device fetches both.
    pub texel_fetch: Option<TexelLimits>,
    pub timestamp_period_ns: f32,
    /// The bits of a timestamp the compute queue writes (0: no timestamps).
    pub timestamp_bits: u32,
    /// A queue family with compute: one without graphics where the device has it (NVIDIA's
    /// and AMD's compute queues, which a desktop's rendering does not share).
    pub compute_queue_family: Option<u32>,
    /// `VkPhysicalDeviceIDProperties::deviceUUID` (NVIDIA's equals the CUDA UUID).
    pub uuid: [u8; 16],
    /// The PCI address, where the driver offers `VK_EXT_pci_bus_info`.
    pub pci: Option<PciAddress>,
    /// `VK_EXT_memory_budget`: how much of its heaps this process may use now.
    pub memory_budget: bool,
    /// `VK_KHR_pipeline_executable_properties`: compiled kernels' statistics
    /// (`VKDIFF_PIPELINE_STATS=1`).
    pub pipeline_statistics: bool,
}

impl DeviceInfo {
    /// The UUID as `vkdiff devices` prints it: 32 lowercase hex digits in 8-4-4-4-12 groups.
    pub fn uuid_text(&self) -> String {
        let hex = self.uuid_hex();
        format!("{}-{}-{}-{}-{}", &hex[..8], &hex[8..12], &hex[12..16], &hex[16..20], &hex[20..])
    }

    /// The UUID as 32 lowercase hex digits.
    pub fn uuid_hex(&self) -> String {
        self.uuid.iter().map(|b| format!("{b:02x}")).collect()
    }

    /// Whether the compute queue writes timestamps (`vkdiff bench --profile`).
    pub fn timestamps(&self) -> bool {
        self.timestamp_bits > 0
    }

    /// Why vkdiff cannot run on this device, if it cannot.
    pub fn unsupported_reason(&self) -> Option<String> {
        if self.api_version < (1, 2, 0) {
            return Some(format!("Vulkan {}.{} < 1.2", self.api_version.0, self.api_version.1));
        }
        if self.compute_queue_family.is_none() {
            return Some("no compute queue".into());
        }
        if !self.subgroup_shuffle || !self.subgroup_arithmetic {
            return Some("no subgroup shuffle/arithmetic operations in compute shaders".into());
        }
        if !self.zero_init_workgroup {
            return Some(
                "no shaderZeroInitializeWorkgroupMemory (Vulkan 1.3 or VK_KHR_zero_initialize_workgroup_memory)".into(),
            );
        }
        None
    }

    /// The byte alignment every storage binding's offset keeps (at least 4: kernels read words).
    pub fn binding_alignment(&self) -> u64 {
        self.min_storage_offset_alignment.max(4)
    }

    /// Whether f16 storage with f32 arithmetic (`--precision f16`) can run here.
    pub fn supports_f16(&self) -> bool {
        self.shader_f16 && self.storage_16bit
    }

    /// The cooperative variant this device runs (`VKDIFF_FRAGMENT`'s shape where one is asked
    /// for); None where its matrix units fit no variant or it cannot run them (f16 storage and
    /// arithmetic, the features above).
    pub fn cooperative_variant(&self) -> Option<Fragment> {
        if !self.cooperative_features || !self.supports_f16() {
            return None;
        }
        let pinnable = |width| self.can_use_subgroup(width);
        matrix_units::pick(&self.matrix_shapes, &self.flexible_shapes, pinnable, self.fragment_request)
    }

    /// Whether a kernel written for a subgroup of exactly `size` lanes can be pinned to it.
    pub fn can_use_subgroup(&self, size: u32) -> bool {
        match self.subgroup_size_range {
            Some((lo, hi)) => (lo..=hi).contains(&size),
            None => self.subgroup_size == size,
        }
    }
}

fn has_extension(instance: &ash::Instance, pd: vk::PhysicalDevice, name: &CStr) -> bool {
    // SAFETY: pd comes from this instance.
    let exts = unsafe { instance.enumerate_device_extension_properties(pd) }.unwrap_or_default();
    exts.iter().any(|e| e.extension_name_as_c_str() == Ok(name))
}

/// Whether the device is a portability implementation (MoltenVK), which must then be created
/// with `VK_KHR_portability_subset` enabled.
pub(crate) fn is_portability_subset(instance: &ash::Instance, pd: vk::PhysicalDevice) -> bool {
    has_extension(instance, pd, ash::khr::portability_subset::NAME)
}

pub(crate) fn describe(
    entry: &ash::Entry,
    instance: &ash::Instance,
    pd: vk::PhysicalDevice,
    (index, api): (usize, (u32, u32)),
    fragment_request: Option<(u32, u32, u32)>,
) -> DeviceInfo {
    // SAFETY: pd comes from this instance.
    let reported = unsafe { instance.get_physical_device_properties(pd) }.api_version;
    let reported = (vk::api_version_major(reported), vk::api_version_minor(reported), vk::api_version_patch(reported));
    let api_version = if (reported.0, reported.1) > api { (api.0, api.1, 0) } else { reported };
    let core13 = api_version >= (1, 3, 0);
    // 1.3 structs only on 1.3 devices; the 1.2 path reads their extensions' equivalents.
    let extension = |name: &CStr| has_extension(instance, pd, name);
    let size_control_extension = !core13 && extension(ash::ext::subgroup_size_control::NAME);
    let zero_init_extension = !core13 && extension(ash::khr::zero_initialize_workgroup_memory::NAME);
    let cooperative_extension = extension(ash::khr::cooperative_matrix::NAME);
    let cooperative2_extension = cooperative_extension && extension(CooperativeMatrix2Features::EXTENSION);
    let pci_extension = extension(ash::ext::pci_bus_info::NAME);
    let memory_budget = extension(ash::ext::memory_budget::NAME);
    let pipeline_statistics = extension(ash::khr::pipeline_executable_properties::NAME);

    let mut subgroup = vk::PhysicalDeviceSubgroupProperties::default();
    let mut size_control = vk::PhysicalDeviceSubgroupSizeControlProperties::default();
    let mut driver = vk::PhysicalDeviceDriverProperties::default();
    let mut maintenance3 = vk::PhysicalDeviceMaintenance3Properties::default();
    let mut ids = vk::PhysicalDeviceIDProperties::default();
    let mut pci = vk::PhysicalDevicePCIBusInfoPropertiesEXT::default();
    let mut props2 = vk::PhysicalDeviceProperties2::default()
        .push_next(&mut subgroup)
        .push_next(&mut maintenance3)
        .push_next(&mut ids)
        .push_next(&mut driver);
    if core13 || size_control_extension {
        props2 = props2.push_next(&mut size_control);
    }
    if pci_extension {
        props2 = props2.push_next(&mut pci);
    }
    let mut f11 = vk::PhysicalDeviceVulkan11Features::default();
    let mut f12 = vk::PhysicalDeviceVulkan12Features::default();
    let mut f13 = vk::PhysicalDeviceVulkan13Features::default();
    let mut size_control_features = vk::PhysicalDeviceSubgroupSizeControlFeatures::default();
    let mut zero_init = vk::PhysicalDeviceZeroInitializeWorkgroupMemoryFeatures::default();
    let mut cooperative = vk::PhysicalDeviceCooperativeMatrixFeaturesKHR::default();
    let mut cooperative2 = CooperativeMatrix2Features::enabling(&[]);
    let mut feats2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut f11).push_next(&mut f12);
    if core13 {
        feats2 = feats2.push_next(&mut f13);
    }
    if size_control_extension {
        feats2 = feats2.push_next(&mut size_control_features);
    }
    if zero_init_extension {
        feats2 = feats2.push_next(&mut zero_init);
    }
    if cooperative_extension {
        feats2 = feats2.push_next(&mut cooperative);
    }
    if cooperative2_extension {
        feats2 = feats2.push_next(&mut cooperative2);
    }
    // SAFETY: pd comes from this instance; the chained structs live until the calls return.
    let (mem, families) = unsafe {
        instance.get_physical_device_properties2(pd, &mut props2);
        instance.get_physical_device_features2(pd, &mut feats2);
        (instance.get_physical_device_memory_properties(pd), instance.get_physical_device_queue_family_properties(pd))
    };
    let shader_int64 = feats2.features.shader_int64 == vk::TRUE;
    let subgroup_size_control =
        if core13 { f13.subgroup_size_control } else { size_control_features.subgroup_size_control };
    let zero_init_workgroup = if core13 {
        f13.shader_zero_initialize_workgroup_memory
    } else {
        zero_init.shader_zero_initialize_workgroup_memory
    };
    let p = props2.properties;
    let family = compute_family(&families);
    let device_local_bytes = mem.memory_heaps[..mem.memory_heap_count as usize]
        .iter()
        .filter(|h| h.flags.contains(vk::MemoryHeapFlags::DEVICE_LOCAL))
        .map(|h| h.size)
        .max()
        .unwrap_or(0);
    let compute = vk::ShaderStageFlags::COMPUTE;
    let ops = subgroup.supported_operations;
    let size_range = (subgroup_size_control == vk::TRUE
        && size_control.required_subgroup_size_stages.contains(compute))
    .then_some((size_control.min_subgroup_size, size_control.max_subgroup_size));
    let text = |s: &[std::ffi::c_char]| {
        // SAFETY: Vulkan strings are NUL-terminated within their fixed arrays.
        unsafe { CStr::from_ptr(s.as_ptr()) }.to_string_lossy().into_owned()
    };
    DeviceInfo {
        index,
        name: text(&p.device_name),
        kind: DeviceKind::from_vk(p.device_type),
        vendor_id: p.vendor_id,
        driver: format!("{} {}", text(&driver.driver_name), text(&driver.driver_info)).trim().to_string(),
        lavapipe_mesa: (driver.driver_id == vk::DriverId::MESA_LLVMPIPE)
            .then(|| mesa_version(&text(&driver.driver_info)))
            .flatten(),
        api_version,
        shader_f16: f12.shader_float16 == vk::TRUE,
        shader_int64,
        storage_16bit: f11.storage_buffer16_bit_access == vk::TRUE
            && f11.uniform_and_storage_buffer16_bit_access == vk::TRUE,
        zero_init_workgroup: zero_init_workgroup == vk::TRUE,
        zero_init_extension,
        size_control_extension: size_control_extension && size_range.is_some(),
        subgroup_size: subgroup.subgroup_size,
        subgroup_size_range: size_range,
        subgroup_shuffle: subgroup.supported_stages.contains(compute)
            && ops.contains(vk::SubgroupFeatureFlags::SHUFFLE),
        subgroup_arithmetic: subgroup.supported_stages.contains(compute)
            && ops.contains(vk::SubgroupFeatureFlags::ARITHMETIC),
        matrix_shapes: if cooperative_extension { matrix_units::query(entry, instance, pd) } else { Vec::new() },
        fragment_request,
        cooperative_matrix2: if cooperative2_extension { cooperative2.reported() } else { Vec::new() },
        flexible_shapes: if cooperative2.flexible_dimensions() {
            flexible_dimensions::query(entry, instance, pd)
        } else {
            Vec::new()
        },
        cooperative_features: cooperative.cooperative_matrix == vk::TRUE && f12.vulkan_memory_model == vk::TRUE,
        max_storage_buffer_range: p.limits.max_storage_buffer_range as u64,
        max_shared_memory: p.limits.max_compute_shared_memory_size,
        max_workgroup_invocations: p.limits.max_compute_work_group_invocations,
        max_workgroup_count: p.limits.max_compute_work_group_count,
        max_push_constants: p.limits.max_push_constants_size,
        max_allocation: maintenance3.max_memory_allocation_size,
        device_local_bytes,
        min_storage_offset_alignment: p.limits.min_storage_buffer_offset_alignment,
        texel_fetch: crate::texel_views::limits(instance, pd, &p.limits),
        timestamp_period_ns: p.limits.timestamp_period,
        timestamp_bits: family.map_or(0, |f| families[f as usize].timestamp_valid_bits),
        compute_queue_family: family,
        uuid: ids.device_uuid,
        pci: pci_extension.then_some(PciAddress {
            domain: pci.pci_domain,
            bus: pci.pci_bus,
            device: pci.pci_device,
            function: pci.pci_function,
        }),
        memory_budget,
        pipeline_statistics,
    }
}

/// The queue family to compute on: the first with compute and without graphics, else the first
/// with compute.
fn compute_family(families: &[vk::QueueFamilyProperties]) -> Option<u32> {
    let compute = |f: &&vk::QueueFamilyProperties| f.queue_flags.contains(vk::QueueFlags::COMPUTE);
    let dedicated = families.iter().position(|f| compute(&f) && !f.queue_flags.contains(vk::QueueFlags::GRAPHICS));
    dedicated.or_else(|| families.iter().position(|f| compute(&f))).map(|i| i as u32)
}

/// Every Vulkan device on this machine, described under `settings`; `env` says where the loader
/// looked for drivers.
pub fn list_devices(settings: &Settings, env: &Environment) -> Result<Vec<DeviceInfo>> {
    let vulkan = crate::instance::shared(settings, &|| searched_drivers(env))?;
    // SAFETY: the instance lives as long as the process.
    let pds = unsafe { vulkan.raw.enumerate_physical_devices() }.vk("vkEnumeratePhysicalDevices")?;
    let describe = |(i, &pd)| describe(&vulkan.entry, &vulkan.raw, pd, (i, vulkan.api), settings.fragment);
    Ok(pds.iter().enumerate().map(describe).collect())
}

/// Where the loader looked for drivers, for the error that found none.
pub(crate) fn searched_drivers(env: &Environment) -> String {
    match env.get("VK_DRIVER_FILES").or_else(|| env.get("VK_ICD_FILENAMES")) {
        Some(list) => format!("VK_DRIVER_FILES={list}"),
        None => "no driver manifest in the loader's icd.d folders (/usr/share/vulkan/icd.d and the like)".into(),
    }
}

/// Mesa's (major, minor) from lavapipe's driver info ("Mesa 25.0.7-2~bpo12+1 (LLVM 15.0.6)"):
/// lavapipe reports `driverVersion` as 1, not Mesa's version.
fn mesa_version(driver_info: &str) -> Option<(u32, u32)> {
    let version = driver_info.split_whitespace().skip_while(|w| *w != "Mesa").nth(1)?;
    let mut numbers = version.split(|c: char| !c.is_ascii_digit()).map(str::parse::<u32>);
    Some((numbers.next()?.ok()?, numbers.next()?.ok()?))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A usable 1.3 device of `kind` for the choice tests (`usable: false` lacks shuffles).
    pub(crate) fn device(index: usize, kind: DeviceKind, usable: bool) -> DeviceInfo {
        DeviceInfo {
            index,
            name: format!("dev{index}"),
            kind,
            vendor_id: 0,
            driver: String::new(),
            lavapipe_mesa: None,
            api_version: (1, 3, 0),
            shader_f16: true,
            shader_int64: true,
            storage_16bit: true,
            zero_init_workgroup: true,
            zero_init_extension: false,
            size_control_extension: false,
            subgroup_size: 32,
            subgroup_size_range: None,
            subgroup_shuffle: usable,
            subgroup_arithmetic: true,
            matrix_shapes: Vec::new(),
            flexible_shapes: Vec::new(),
            cooperative_matrix2: Vec::new(),
            fragment_request: None,
            cooperative_features: false,
            max_storage_buffer_range: 1 << 27,
            max_shared_memory: 32768,
            max_workgroup_invocations: 1024,
            max_workgroup_count: [65535; 3],
            max_push_constants: 128,
            max_allocation: 1 << 31,
            device_local_bytes: 1 << 31,
            min_storage_offset_alignment: 16,
            texel_fetch: None,
            timestamp_period_ns: 1.0,
            timestamp_bits: 64,
            compute_queue_family: Some(0),
            uuid: [index as u8; 16],
            pci: None,
            memory_budget: false,
            pipeline_statistics: false,
        }
    }

    #[test]
    fn reads_mesa_versions_from_lavapipe_driver_info() {
        assert_eq!(mesa_version("Mesa 25.0.7-2~bpo12+1 (LLVM 15.0.6)"), Some((25, 0)));
        assert_eq!(mesa_version("Mesa 22.3.6 (LLVM 15.0.6)"), Some((22, 3)));
        assert_eq!(mesa_version("Mesa 26.1.0-devel (git-1a2b3c4)"), Some((26, 1)));
        assert_eq!(mesa_version("(LLVM 19.1.7)"), None);
        assert_eq!(mesa_version("Mesa"), None);
    }

    #[test]
    fn computes_on_a_queue_without_graphics_where_there_is_one() {
        let family = |flags| vk::QueueFamilyProperties { queue_flags: flags, queue_count: 1, ..Default::default() };
        let (g, c, t) = (vk::QueueFlags::GRAPHICS, vk::QueueFlags::COMPUTE, vk::QueueFlags::TRANSFER);
        // NVIDIA: graphics+compute, transfer, compute; lavapipe: one family with everything.
        assert_eq!(compute_family(&[family(g | c | t), family(t), family(c | t)]), Some(2));
        assert_eq!(compute_family(&[family(g | c | t)]), Some(0));
        assert_eq!(compute_family(&[family(g), family(t)]), None);
    }
}
