//! One-off command buffers for transfers outside a recording (staging copies, fills).

use crate::context::Context;
use crate::error::{Error, Result, VkContext};
use ash::vk;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Whether any context's wait for the device timed out in this process (see [`device_hung`]).
static ANY_HUNG: AtomicBool = AtomicBool::new(false);

/// Whether a wait for a device timed out in this process: its driver may still run that work,
/// on a CPU device in this process's own threads, so the process should end without the
/// libraries' exit handlers, which tear down what those threads use (seen as a segmentation
/// fault on lavapipe after a timed-out submission).
pub fn device_hung() -> bool {
    ANY_HUNG.load(Ordering::SeqCst)
}

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
        if !ctx.shared.hung.load(Ordering::SeqCst) {
            device.destroy_command_pool(pool, None);
        }
        result
    }
}

/// Submits one recorded command buffer and blocks until the device has finished it.
pub(crate) fn submit_and_wait(ctx: &Context, cmd: vk::CommandBuffer) -> Result<()> {
    submit_groups_and_wait(ctx, &[&[cmd]], Duration::ZERO).map(drop)
}

/// Submits `groups` of chunks in order, one `vkQueueSubmit` each (a GPU watchdog times each
/// alone), then waits for each in turn, at most the context's submission timeout apiece, and
/// `compiling` longer while the driver compiles kernels among them.
/// Returns the time between one submission's end and the next's (the first's from its
/// submission): queued back to back, about each submission's run time.
pub(crate) fn submit_groups_and_wait(
    ctx: &Context,
    groups: &[&[vk::CommandBuffer]],
    compiling: Duration,
) -> Result<Vec<Duration>> {
    let device = &ctx.shared.device;
    let timeout = ctx.choices().submit_budget.timeout + compiling;
    let mut fences = Vec::with_capacity(groups.len());
    let mut times = Vec::with_capacity(groups.len());
    // SAFETY: each chunk is fully recorded; the queue is externally synchronised by its mutex;
    // the fences are destroyed only once signalled (or never, on a hung device).
    unsafe {
        let result = (|| {
            for group in groups {
                let fence = device.create_fence(&vk::FenceCreateInfo::default(), None).vk("vkCreateFence")?;
                fences.push(fence);
                let submit = [vk::SubmitInfo::default().command_buffers(group)];
                let queue = ctx.shared.queue.lock().unwrap();
                device.queue_submit(*queue, &submit, fence).vk("vkQueueSubmit")?;
            }
            let mut last = Instant::now();
            for fence in &fences {
                match device.wait_for_fences(&[*fence], true, timeout.as_nanos().min(u64::MAX as u128) as u64) {
                    Err(vk::Result::TIMEOUT) => {
                        // The device may still run these chunks: nothing they use is freed.
                        ctx.shared.hung.store(true, Ordering::SeqCst);
                        ANY_HUNG.store(true, Ordering::SeqCst);
                        return Err(Error::SubmitTimeout { seconds: timeout.as_secs_f64() });
                    }
                    other => other.vk("vkWaitForFences")?,
                }
                times.push(last.elapsed());
                last = Instant::now();
            }
            Ok(times)
        })();
        if !ctx.shared.hung.load(Ordering::SeqCst) {
            for fence in fences {
                device.destroy_fence(fence, None);
            }
        }
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
