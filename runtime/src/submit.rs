//! One-off command buffers for transfers outside a recording (staging copies, fills).

use crate::context::Context;
use crate::error::{Result, VkContext};
use ash::vk;

/// Records `f` into a fresh command buffer, submits it and waits for it to finish.
pub(crate) fn submit_once(ctx: &Context, f: impl FnOnce(&ash::Device, vk::CommandBuffer)) -> Result<()> {
    let device = &ctx.shared.device;
    // SAFETY: every handle is created, used and destroyed here; the fence wait ends all use.
    unsafe {
        let pool = device
            .create_command_pool(
                &vk::CommandPoolCreateInfo::default()
                    .queue_family_index(ctx.shared.queue_family)
                    .flags(vk::CommandPoolCreateFlags::TRANSIENT),
                None,
            )
            .vk("vkCreateCommandPool")?;
        let result = (|| {
            let cmd = device
                .allocate_command_buffers(
                    &vk::CommandBufferAllocateInfo::default().command_pool(pool).command_buffer_count(1),
                )
                .vk("vkAllocateCommandBuffers")?[0];
            device
                .begin_command_buffer(
                    cmd,
                    &vk::CommandBufferBeginInfo::default().flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
                )
                .vk("vkBeginCommandBuffer")?;
            // Earlier kernels' and transfers' writes before this transfer; its writes before the
            // host reads a staging buffer and before later submissions (which also wait on
            // their own first barrier).
            let transfer = vk::PipelineStageFlags::TRANSFER;
            let writes = vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE;
            memory_barrier(
                device,
                cmd,
                (vk::PipelineStageFlags::COMPUTE_SHADER | transfer, writes),
                (transfer, vk::AccessFlags::TRANSFER_READ | vk::AccessFlags::TRANSFER_WRITE),
            );
            f(device, cmd);
            memory_barrier(
                device,
                cmd,
                (transfer, vk::AccessFlags::TRANSFER_WRITE),
                (vk::PipelineStageFlags::HOST, vk::AccessFlags::HOST_READ),
            );
            device.end_command_buffer(cmd).vk("vkEndCommandBuffer")?;
            submit_and_wait(ctx, cmd)
        })();
        device.destroy_command_pool(pool, None);
        result
    }
}

/// Submits one recorded command buffer and blocks until the device has finished it.
pub(crate) fn submit_and_wait(ctx: &Context, cmd: vk::CommandBuffer) -> Result<()> {
    let device = &ctx.shared.device;
    // SAFETY: cmd is fully recorded; the queue is externally synchronised by its mutex.
    unsafe {
        let fence = device.create_fence(&vk::FenceCreateInfo::default(), None).vk("vkCreateFence")?;
        let cmds = [cmd];
        let submit = [vk::SubmitInfo::default().command_buffers(&cmds)];
        let result = {
            let queue = ctx.shared.queue.lock().unwrap();
            device.queue_submit(*queue, &submit, fence).vk("vkQueueSubmit")
        }
        .and_then(|_| device.wait_for_fences(&[fence], true, u64::MAX).vk("vkWaitForFences"));
        device.destroy_fence(fence, None);
        result
    }
}

/// Records a global memory barrier from `(stages, accesses)` to `(stages, accesses)`.
///
/// # Safety
/// `cmd` must be recording.
pub(crate) unsafe fn memory_barrier(
    device: &ash::Device,
    cmd: vk::CommandBuffer,
    (src_stage, src): (vk::PipelineStageFlags, vk::AccessFlags),
    (dst_stage, dst): (vk::PipelineStageFlags, vk::AccessFlags),
) {
    let barrier = [vk::MemoryBarrier::default().src_access_mask(src).dst_access_mask(dst)];
    // SAFETY: the caller guarantees cmd is recording.
    unsafe { device.cmd_pipeline_barrier(cmd, src_stage, dst_stage, vk::DependencyFlags::empty(), &barrier, &[], &[]) };
}
