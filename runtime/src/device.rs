//! Vulkan instance, physical-device discovery and the choice of device.

use crate::error::{Error, Result, VkContext};
use crate::matrix_units::{self, MatrixShape};
use crate::validation::Validation;
use ash::vk;
use std::ffi::CStr;
use vkdiff_setting::Message;

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
    /// 16-bit values in storage buffers: `storageBuffer16BitAccess` and
    /// `uniformAndStorageBuffer16BitAccess` (naga declares the second capability for them).
    pub storage_16bit: bool,
    /// `shaderZeroInitializeWorkgroupMemory` (core in 1.3, else its KHR extension): the kernels
    /// zero their workgroup memory natively (naga's polyfill is seconds of JIT on lavapipe).
    pub zero_init_workgroup: bool,
    /// Whether `zero_init_workgroup` comes from the extension, which must then be enabled.
    pub zero_init_extension: bool,
    pub subgroup_size: u32,
    pub subgroup_size_range: Option<(u32, u32)>,
    pub subgroup_shuffle: bool,
    pub subgroup_arithmetic: bool,
    /// The product shapes `VK_KHR_cooperative_matrix` lists (empty without it).
    pub matrix_shapes: Vec<MatrixShape>,
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
    pub timestamp_period_ns: f32,
    pub timestamps: bool,
    pub compute_queue_family: Option<u32>,
}

impl DeviceInfo {
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

    /// The cooperative GEMM/convolution variant this device runs, as (fragment size, subgroup
    /// width); None where its matrix units fit no variant or it cannot run them (f16 storage
    /// and arithmetic, the features above).
    pub fn cooperative_variant(&self) -> Option<(u32, u32)> {
        if !self.cooperative_features || !self.supports_f16() {
            return None;
        }
        matrix_units::pick(&self.matrix_shapes, |width| self.can_use_subgroup(width))
    }

    /// Whether a kernel written for a subgroup of exactly `size` lanes can be pinned to it.
    pub fn can_use_subgroup(&self, size: u32) -> bool {
        match self.subgroup_size_range {
            Some((lo, hi)) => (lo..=hi).contains(&size),
            None => self.subgroup_size == size,
        }
    }
}

pub(crate) fn load_entry() -> Result<ash::Entry> {
    // SAFETY: loading the system Vulkan loader; its symbols follow the Vulkan ABI.
    unsafe { ash::Entry::load() }.map_err(|e| Error::NoLoader(e.to_string()))
}

/// vkdiff's instance, validated under `VKDIFF_VALIDATE=1`. Where the loader offers
/// `VK_KHR_portability_enumeration`, portability devices (MoltenVK) are listed too.
pub(crate) fn create_instance(entry: &ash::Entry) -> Result<(ash::Instance, Option<Validation>)> {
    let app = vk::ApplicationInfo::default()
        .application_name(c"vkdiff")
        .engine_name(c"vkdiff")
        .api_version(vk::API_VERSION_1_3);
    // SAFETY: a plain query of the loader.
    let available =
        unsafe { entry.enumerate_instance_extension_properties(None) }.vk("vkEnumerateInstanceExtensionProperties")?;
    let portability = ash::khr::portability_enumeration::NAME;
    let mut info = vk::InstanceCreateInfo::default().application_info(&app);
    let mut extensions = Vec::new();
    if available.iter().any(|e| e.extension_name_as_c_str() == Ok(portability)) {
        extensions.push(portability.as_ptr());
        info = info.flags(vk::InstanceCreateFlags::ENUMERATE_PORTABILITY_KHR);
    }
    crate::validation::create_instance(entry, info, extensions)
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
    index: usize,
) -> DeviceInfo {
    let mut subgroup = vk::PhysicalDeviceSubgroupProperties::default();
    let mut size_control = vk::PhysicalDeviceSubgroupSizeControlProperties::default();
    let mut driver = vk::PhysicalDeviceDriverProperties::default();
    let mut maintenance3 = vk::PhysicalDeviceMaintenance3Properties::default();
    let mut props2 = vk::PhysicalDeviceProperties2::default()
        .push_next(&mut subgroup)
        .push_next(&mut maintenance3)
        .push_next(&mut size_control)
        .push_next(&mut driver);
    let mut f11 = vk::PhysicalDeviceVulkan11Features::default();
    let mut f12 = vk::PhysicalDeviceVulkan12Features::default();
    let mut f13 = vk::PhysicalDeviceVulkan13Features::default();
    let mut zero_init = vk::PhysicalDeviceZeroInitializeWorkgroupMemoryFeatures::default();
    let zero_init_extension = has_extension(instance, pd, ash::khr::zero_initialize_workgroup_memory::NAME);
    let mut cooperative = vk::PhysicalDeviceCooperativeMatrixFeaturesKHR::default();
    let cooperative_extension = has_extension(instance, pd, ash::khr::cooperative_matrix::NAME);
    let mut feats2 = vk::PhysicalDeviceFeatures2::default()
        .push_next(&mut f11)
        .push_next(&mut f12)
        .push_next(&mut f13)
        .push_next(&mut zero_init);
    if cooperative_extension {
        feats2 = feats2.push_next(&mut cooperative);
    }
    // SAFETY: pd comes from this instance; the chained structs live until the calls return.
    let (mem, families) = unsafe {
        instance.get_physical_device_properties2(pd, &mut props2);
        instance.get_physical_device_features2(pd, &mut feats2);
        (instance.get_physical_device_memory_properties(pd), instance.get_physical_device_queue_family_properties(pd))
    };
    let p = props2.properties;
    let v = p.api_version;
    let api_version = (vk::api_version_major(v), vk::api_version_minor(v), vk::api_version_patch(v));
    let family = families.iter().position(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE)).map(|i| i as u32);
    let timestamps = family.is_some_and(|f| families[f as usize].timestamp_valid_bits > 0);
    let device_local_bytes = mem.memory_heaps[..mem.memory_heap_count as usize]
        .iter()
        .filter(|h| h.flags.contains(vk::MemoryHeapFlags::DEVICE_LOCAL))
        .map(|h| h.size)
        .max()
        .unwrap_or(0);
    let compute = vk::ShaderStageFlags::COMPUTE;
    let ops = subgroup.supported_operations;
    let size_range = (f13.subgroup_size_control == vk::TRUE
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
        storage_16bit: f11.storage_buffer16_bit_access == vk::TRUE
            && f11.uniform_and_storage_buffer16_bit_access == vk::TRUE,
        zero_init_workgroup: zero_init.shader_zero_initialize_workgroup_memory == vk::TRUE,
        zero_init_extension: api_version < (1, 3, 0) && zero_init_extension,
        subgroup_size: subgroup.subgroup_size,
        subgroup_size_range: size_range,
        subgroup_shuffle: subgroup.supported_stages.contains(compute)
            && ops.contains(vk::SubgroupFeatureFlags::SHUFFLE),
        subgroup_arithmetic: subgroup.supported_stages.contains(compute)
            && ops.contains(vk::SubgroupFeatureFlags::ARITHMETIC),
        matrix_shapes: if cooperative_extension { matrix_units::query(entry, instance, pd) } else { Vec::new() },
        cooperative_features: cooperative.cooperative_matrix == vk::TRUE && f12.vulkan_memory_model == vk::TRUE,
        max_storage_buffer_range: p.limits.max_storage_buffer_range as u64,
        max_shared_memory: p.limits.max_compute_shared_memory_size,
        max_workgroup_invocations: p.limits.max_compute_work_group_invocations,
        max_workgroup_count: p.limits.max_compute_work_group_count,
        max_push_constants: p.limits.max_push_constants_size,
        max_allocation: maintenance3.max_memory_allocation_size,
        device_local_bytes,
        min_storage_offset_alignment: p.limits.min_storage_buffer_offset_alignment,
        timestamp_period_ns: p.limits.timestamp_period,
        timestamps,
        compute_queue_family: family,
    }
}

/// Every Vulkan device on this machine, described.
pub fn list_devices() -> Result<Vec<DeviceInfo>> {
    let entry = load_entry()?;
    let (instance, validation) = create_instance(&entry)?;
    // SAFETY: the instance is valid until destroyed below.
    let infos = unsafe { instance.enumerate_physical_devices() }
        .vk("vkEnumeratePhysicalDevices")
        .map(|pds| pds.iter().enumerate().map(|(i, &pd)| describe(&entry, &instance, pd, i)).collect());
    // SAFETY: nothing created from the instance outlives it; the messenger goes first.
    unsafe {
        if let Some(v) = &validation {
            v.destroy();
        }
        instance.destroy_instance(None)
    };
    infos
}

/// Which device to use: `requested` (the `device` setting), else `VKDIFF_DEVICE`, else the first
/// usable discrete GPU, then integrated, virtual, CPU (lavapipe).
pub fn choose(devices: &[DeviceInfo], requested: Option<usize>) -> Result<usize> {
    let from_env = std::env::var("VKDIFF_DEVICE").ok().filter(|s| !s.is_empty());
    let (index, requested_by) = match (requested, from_env) {
        (Some(i), _) => (Some(i), Message::setting("device")),
        (None, Some(s)) => (
            Some(s.trim().parse().map_err(|_| Error::BadDeviceSpec(format!("VKDIFF_DEVICE={s}")))?),
            Message::text("VKDIFF_DEVICE"),
        ),
        (None, None) => (None, Message::default()),
    };
    if devices.is_empty() {
        return Err(Error::NoDevice);
    }
    if let Some(index) = index {
        let d = devices.get(index).ok_or(Error::BadDeviceIndex { index, count: devices.len(), requested_by })?;
        if let Some(reason) = d.unsupported_reason() {
            return Err(Error::Unsupported { device: d.name.clone(), reason });
        }
        return Ok(index);
    }
    devices
        .iter()
        .filter(|d| d.unsupported_reason().is_none())
        .min_by_key(|d| (d.kind, d.index))
        .map(|d| d.index)
        .ok_or_else(|| Error::Unsupported {
            device: devices[0].name.clone(),
            reason: devices[0].unsupported_reason().unwrap_or_default(),
        })
}

/// Mesa's (major, minor) from lavapipe's driver info ("Mesa 25.0.7-2~bpo12+1 (LLVM 15.0.6)"):
/// lavapipe reports `driverVersion` as 1, not Mesa's version.
fn mesa_version(driver_info: &str) -> Option<(u32, u32)> {
    let version = driver_info.split_whitespace().skip_while(|w| *w != "Mesa").nth(1)?;
    let mut numbers = version.split(|c: char| !c.is_ascii_digit()).map(str::parse::<u32>);
    Some((numbers.next()?.ok()?, numbers.next()?.ok()?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_mesa_versions_from_lavapipe_driver_info() {
        assert_eq!(mesa_version("Mesa 25.0.7-2~bpo12+1 (LLVM 15.0.6)"), Some((25, 0)));
        assert_eq!(mesa_version("Mesa 22.3.6 (LLVM 15.0.6)"), Some((22, 3)));
        assert_eq!(mesa_version("Mesa 26.1.0-devel (git-1a2b3c4)"), Some((26, 1)));
        assert_eq!(mesa_version("(LLVM 19.1.7)"), None);
        assert_eq!(mesa_version("Mesa"), None);
    }

    fn device(index: usize, kind: DeviceKind, usable: bool) -> DeviceInfo {
        DeviceInfo {
            index,
            name: format!("dev{index}"),
            kind,
            vendor_id: 0,
            driver: String::new(),
            lavapipe_mesa: None,
            api_version: (1, 3, 0),
            shader_f16: true,
            storage_16bit: true,
            zero_init_workgroup: true,
            zero_init_extension: false,
            subgroup_size: 32,
            subgroup_size_range: None,
            subgroup_shuffle: usable,
            subgroup_arithmetic: true,
            matrix_shapes: Vec::new(),
            cooperative_features: false,
            max_storage_buffer_range: 1 << 27,
            max_shared_memory: 32768,
            max_workgroup_invocations: 1024,
            max_workgroup_count: [65535; 3],
            max_push_constants: 128,
            max_allocation: 1 << 31,
            device_local_bytes: 1 << 31,
            min_storage_offset_alignment: 16,
            timestamp_period_ns: 1.0,
            timestamps: true,
            compute_queue_family: Some(0),
        }
    }

    #[test]
    fn prefers_discrete_then_integrated_then_cpu() {
        // Run without VKDIFF_DEVICE influence: only `requested` paths read it after None.
        let devs = [
            device(0, DeviceKind::Cpu, true),
            device(1, DeviceKind::Integrated, true),
            device(2, DeviceKind::Discrete, true),
        ];
        assert_eq!(choose(&devs, Some(0)).unwrap(), 0);
        if std::env::var("VKDIFF_DEVICE").is_err() {
            assert_eq!(choose(&devs, None).unwrap(), 2);
            assert_eq!(choose(&devs[..2], None).unwrap(), 1);
            assert_eq!(choose(&devs[..1], None).unwrap(), 0);
        }
    }

    #[test]
    fn skips_unusable_devices_and_rejects_them_when_asked() {
        let devs = [device(0, DeviceKind::Discrete, false), device(1, DeviceKind::Cpu, true)];
        if std::env::var("VKDIFF_DEVICE").is_err() {
            assert_eq!(choose(&devs, None).unwrap(), 1);
        }
        let err = choose(&devs, Some(0)).unwrap_err().to_string();
        assert!(err.contains("dev0") && err.contains("subgroup"), "{err}");
        assert!(choose(&devs, Some(5)).unwrap_err().to_string().contains("only 2"));
        assert!(matches!(choose(&[], None), Err(Error::NoDevice)));
    }

    #[test]
    fn a_device_without_what_the_kernels_declare_is_refused_by_name() {
        let mut dev = device(0, DeviceKind::Discrete, true);
        dev.zero_init_workgroup = false;
        let err = choose(&[dev], Some(0)).unwrap_err().to_string();
        assert!(err.contains("shaderZeroInitializeWorkgroupMemory"), "{err}");
        let mut dev = device(0, DeviceKind::Discrete, true);
        dev.storage_16bit = false;
        assert!(!dev.supports_f16(), "f16 kernels need 16-bit storage access");
    }
}
