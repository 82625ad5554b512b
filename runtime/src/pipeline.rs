//! Compute pipelines, created once per kernel variant and cached for the context's lifetime.

use crate::error::{Result, VkContext};
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
            device.destroy_pipeline(k.pipeline, None);
            device.destroy_pipeline_layout(k.layout, None);
            device.destroy_descriptor_set_layout(k.set_layout, None);
        }
    }
}

impl PipelineCache {
    /// The pipeline for `variant` on `device`, created on first use; `pinned_subgroups`: the
    /// device can require a subgroup size (`VK_EXT_subgroup_size_control`); `statistics`: print
    /// the compiled kernel's statistics (`VKDIFF_PIPELINE_STATS=1`).
    pub(crate) fn kernel(
        &self,
        device: &ash::Device,
        options: (bool, Option<&Statistics>),
        variant: &'static Variant,
        bindings: u32,
    ) -> Result<Arc<Kernel>> {
        let key = variant as *const Variant as usize;
        let mut cache = self.kernels.lock().unwrap();
        if let Some(k) = cache.get(&key) {
            return Ok(k.clone());
        }
        let kernel = Arc::new(create_kernel(device, options, variant, bindings)?);
        cache.insert(key, kernel.clone());
        Ok(kernel)
    }
}

type Statistics = ash::khr::pipeline_executable_properties::Device;

fn create_kernel(
    device: &ash::Device,
    (pinned_subgroups, statistics): (bool, Option<&Statistics>),
    variant: &'static Variant,
    bindings: u32,
) -> Result<Kernel> {
    let layout_bindings: Vec<_> = (0..bindings)
        .map(|b| {
            vk::DescriptorSetLayoutBinding::default()
                .binding(b)
                .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                .descriptor_count(1)
                .stage_flags(vk::ShaderStageFlags::COMPUTE)
        })
        .collect();
    let words = variant.words();
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
        let pipeline = created.map_err(|(_, e)| e).vk("vkCreateComputePipelines")?[0];
        if let Some(loader) = statistics {
            for line in crate::pipeline_stats::describe(loader, pipeline, variant) {
                eprintln!("pipeline statistics: {line}");
            }
        }
        Ok(Kernel { name: variant.kernel, pipeline, layout, set_layout, bindings, dispatched: AtomicBool::new(false) })
    }
}
