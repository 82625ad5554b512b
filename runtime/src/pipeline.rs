//! Compute pipelines, created once per kernel variant and cached for the context's lifetime.

use crate::error::{Result, VkContext};
use crate::pipeline_stats::{self, Statistics};
use ash::vk;
use std::collections::HashMap;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};
use vkdiff_kernels::Variant;

/// Push constants every kernel may use; the guaranteed minimum of `maxPushConstantsSize`.
pub const PUSH_BYTES: u32 = 128;

/// A kernel variant ready to dispatch: `bindings` storage buffers at set 0, push constants.
pub struct Kernel {
    pub name: &'static str,
    /// The compiled variant (its family, dtype and tile and fragment parameters).
    pub variant: &'static Variant,
    pub(crate) pipeline: vk::Pipeline,
    pub(crate) layout: vk::PipelineLayout,
    pub(crate) set_layout: vk::DescriptorSetLayout,
    pub(crate) bindings: u32,
    /// Whether a submission in this process has dispatched it (JIT drivers compile it then).
    pub(crate) dispatched: AtomicBool,
}

#[derive(Default)]
pub(crate) struct PipelineCache {
    kernels: Mutex<HashMap<usize, Arc<Kernel>>>,
}

impl PipelineCache {
    /// SAFETY: the device must be idle and no kernel used again.
    pub(crate) unsafe fn destroy(&self, device: &ash::Device) {
        for (_, k) in self.kernels.lock().unwrap().drain() {
            k.destroy(device);
        }
    }
}

impl PipelineCache {
    /// The pipeline for `variant` on `device`, created on first use; `pinned_subgroups`: the
    /// device can require a subgroup size (`VK_EXT_subgroup_size_control`); `broadcasts`: write
    /// shuffles from constant lanes as broadcasts ([`vkdiff_kernels::constant_broadcasts`]);
    /// `statistics`: print the compiled kernel's statistics (`VKDIFF_PIPELINE_STATS=1`).
    pub(crate) fn kernel(
        &self,
        device: &ash::Device,
        options: (bool, bool, Option<&StatisticsLoader>),
        variant: &'static Variant,
        bindings: u32,
    ) -> Result<Arc<Kernel>> {
        let key = variant as *const Variant as usize;
        let mut cache = self.kernels.lock().unwrap();
        if let Some(k) = cache.get(&key) {
            return Ok(k.clone());
        }
        let (kernel, statistics) = create_kernel(device, options, variant, bindings)?;
        let label = pipeline_stats::variant_label(variant);
        match statistics {
            None => {}
            Some(Ok(executables)) => {
                for each in executables {
                    eprintln!("pipeline statistics: {label}: {}", pipeline_stats::describe(&each));
                }
            }
            Some(Err(e)) => eprintln!("pipeline statistics: {label}: {e}"),
        }
        let kernel = Arc::new(kernel);
        cache.insert(key, kernel.clone());
        Ok(kernel)
    }
}

type StatisticsLoader = ash::khr::pipeline_executable_properties::Device;

/// What `variant` reads at `binding`: a storage buffer, or a uniform texel buffer for B where the
/// variant reads B from texels (TB = 1, binding 1) and for A where it reads A so too (TA = 1,
/// binding 0).
pub(crate) fn descriptor_type(variant: &Variant, binding: u32) -> vk::DescriptorType {
    let texels = match binding {
        0 => variant.param("TA") == Some(1),
        1 => variant.param("TB") == Some(1),
        _ => false,
    };
    if texels {
        vk::DescriptorType::UNIFORM_TEXEL_BUFFER
    } else {
        vk::DescriptorType::STORAGE_BUFFER
    }
}

/// What a driver reported of each executable of a pipeline created with statistics captured, or
/// why it reported nothing.
pub(crate) type Reported = std::result::Result<Vec<Statistics>, String>;

/// The kernel and, where `statistics` is given, what the driver reports of each of its
/// executables (or why it reports nothing).
pub(crate) fn create_kernel(
    device: &ash::Device,
    (pinned_subgroups, broadcasts, statistics): (bool, bool, Option<&StatisticsLoader>),
    variant: &'static Variant,
    bindings: u32,
) -> Result<(Kernel, Option<Reported>)> {
    let layout_bindings: Vec<_> = (0..bindings)
        .map(|b| {
            vk::DescriptorSetLayoutBinding::default()
                .binding(b)
                .descriptor_type(descriptor_type(variant, b))
                .descriptor_count(1)
                .stage_flags(vk::ShaderStageFlags::COMPUTE)
        })
        .collect();
    let words = if broadcasts { vkdiff_kernels::constant_broadcasts(&variant.words()) } else { variant.words() };
    // SAFETY: all create infos point at locals that outlive the calls; handles are destroyed
    // with the cache or right here when pipeline creation fails.
    unsafe {
        let set_layout = device
            .create_descriptor_set_layout(
                &vk::DescriptorSetLayoutCreateInfo::default().bindings(&layout_bindings),
                None,
            )
            .vk("vkCreateDescriptorSetLayout")?;
        let ranges = [vk::PushConstantRange::default().stage_flags(vk::ShaderStageFlags::COMPUTE).size(PUSH_BYTES)];
        let set_layouts = [set_layout];
        let layout = device
            .create_pipeline_layout(
                &vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts).push_constant_ranges(&ranges),
                None,
            )
            .vk("vkCreatePipelineLayout")?;
        let module = device
            .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None)
            .vk("vkCreateShaderModule")?;
        let mut required = vk::PipelineShaderStageRequiredSubgroupSizeCreateInfo::default();
        let mut stage = vk::PipelineShaderStageCreateInfo::default()
            .stage(vk::ShaderStageFlags::COMPUTE)
            .module(module)
            .name(c"main");
        // Kernels built for a subgroup width are pinned to it where the device allows.
        if let (Some(sg), true) = (variant.param("SG"), pinned_subgroups) {
            required = required.required_subgroup_size(sg);
            stage = stage.flags(vk::PipelineShaderStageCreateFlags::REQUIRE_FULL_SUBGROUPS).push_next(&mut required);
        }
        // DISPATCH_BASE: grids past the workgroup-count limit run as based dispatches.
        let mut flags = vk::PipelineCreateFlags::DISPATCH_BASE;
        if statistics.is_some() {
            flags |= vk::PipelineCreateFlags::CAPTURE_STATISTICS_KHR;
        }
        let info = [vk::ComputePipelineCreateInfo::default().flags(flags).stage(stage).layout(layout)];
        let created = device.create_compute_pipelines(vk::PipelineCache::null(), &info, None);
        device.destroy_shader_module(module, None);
        let pipeline = match created {
            Ok(p) => p[0],
            Err((_, e)) => {
                device.destroy_pipeline_layout(layout, None);
                device.destroy_descriptor_set_layout(set_layout, None);
                return Err(e).vk("vkCreateComputePipelines");
            }
        };
        let reported = statistics.map(|loader| pipeline_stats::query(loader, pipeline));
        let kernel = Kernel {
            name: variant.kernel,
            variant,
            pipeline,
            layout,
            set_layout,
            bindings,
            dispatched: AtomicBool::new(false),
        };
        Ok((kernel, reported))
    }
}

impl Kernel {
    /// SAFETY: the device must be done with it, and it is not used again.
    pub(crate) unsafe fn destroy(&self, device: &ash::Device) {
        device.destroy_pipeline(self.pipeline, None);
        device.destroy_pipeline_layout(self.layout, None);
        device.destroy_descriptor_set_layout(self.set_layout, None);
    }
}
