//! Records many dispatches into one command buffer, with barriers only where a dispatch touches
//! a buffer an earlier one wrote (or writes one an earlier one read), and replays it.

use crate::arena::Arena;
use crate::context::Context;
use crate::error::{ensure, Result, VkContext};
use crate::memory::Buffer;
use crate::pipeline::{descriptor_type, Kernel, PUSH_BYTES};
use crate::recording::Recording;
use crate::submit::memory_barrier;
use crate::submit_budget::SubmitBudget;
use crate::tensor::Tensor;
use ash::vk;
use std::collections::HashSet;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Instant;

const SETS_PER_POOL: u32 = 256;
const MAX_BINDINGS: u32 = 8;
/// Timestamp queries per pool (two a dispatch); [`Recording`] reads them back in pools of these.
pub(crate) const QUERIES_PER_POOL: u32 = 512;

/// Command buffer under construction. [`Recorder::finish`] turns it into a replayable
/// [`Recording`].
pub struct Recorder {
    ctx: Context,
    res: Resources,
    /// The chunk being recorded; `res.chunks` holds those before it.
    cmd: vk::CommandBuffer,
    sets_left: u32,
    written: HashSet<vk::Buffer>,
    read: HashSet<vk::Buffer>,
    profile: bool,
    flops: f64,
    budget: SubmitBudget,
    /// FLOPs and dispatches recorded into `cmd` so far.
    chunk_flops: f64,
    chunk_dispatches: u32,
    /// When recording began (see [`crate::HostStats::recording_seconds`]).
    started: Instant,
    /// Temporaries of the ops recorded ([`Recorder::scratch`]).
    scratch: Arena,
}

/// Vulkan objects owned by a recording, destroyed with it.
pub(crate) struct Resources {
    pub(crate) ctx: Context,
    command_pool: vk::CommandPool,
    /// The finished chunks, submitted in order (see [`SubmitBudget`]).
    pub(crate) chunks: Vec<vk::CommandBuffer>,
    descriptor_pools: Vec<vk::DescriptorPool>,
    pub(crate) query_pools: Vec<vk::QueryPool>,
    pub(crate) labels: Vec<&'static str>,
    buffers: Vec<Arc<Buffer>>,
    /// Texel views of those buffers that dispatches read (`texel_views::create`).
    views: Vec<vk::BufferView>,
    pub(crate) kernels: Vec<Arc<Kernel>>,
}

impl Drop for Resources {
    fn drop(&mut self) {
        if self.ctx.shared.hung.load(Ordering::SeqCst) {
            // A timed-out run may still use these: leave them (the process ends anyway).
            std::mem::forget(std::mem::take(&mut self.buffers));
            return;
        }
        let device = &self.ctx.shared.device;
        // SAFETY: recordings are only run synchronously, so nothing is pending.
        unsafe {
            for &p in &self.descriptor_pools {
                device.destroy_descriptor_pool(p, None);
            }
            for &q in &self.query_pools {
                device.destroy_query_pool(q, None);
            }
            for &v in &self.views {
                device.destroy_buffer_view(v, None);
            }
            device.destroy_command_pool(self.command_pool, None);
        }
    }
}

impl Recorder {
    /// Starts a recording; with `profile` (or the context's [`Context::set_profiling`]), every
    /// dispatch is timed with timestamp queries.
    pub fn new(ctx: &Context, profile: bool) -> Result<Recorder> {
        let profile = profile || ctx.profiling();
        ensure(!profile || ctx.info().timestamps(), || {
            format!("device `{}` has no timestamp queries to profile with", ctx.info().name)
        })?;
        let device = &ctx.shared.device;
        // SAFETY: plain object creation on a valid device; Resources destroys them.
        unsafe {
            let command_pool = device
                .create_command_pool(
                    &vk::CommandPoolCreateInfo::default().queue_family_index(ctx.shared.queue_family),
                    None,
                )
                .vk("vkCreateCommandPool")?;
            let res = Resources {
                ctx: ctx.clone(),
                command_pool,
                chunks: Vec::new(),
                descriptor_pools: Vec::new(),
                query_pools: Vec::new(),
                labels: Vec::new(),
                buffers: Vec::new(),
                views: Vec::new(),
                kernels: Vec::new(),
            };
            let mut rec = Recorder {
                ctx: ctx.clone(),
                res,
                cmd: vk::CommandBuffer::null(),
                sets_left: 0,
                written: HashSet::new(),
                read: HashSet::new(),
                profile,
                flops: 0.0,
                budget: ctx.choices().submit_budget,
                chunk_flops: 0.0,
                chunk_dispatches: 0,
                started: Instant::now(),
                scratch: Arena::new(ctx),
            };
            rec.begin_chunk()?;
            Ok(rec)
        }
    }

    /// Starts a command buffer for the next chunk. Its first barrier makes what earlier
    /// submissions wrote (kernels, staging copies, fills, the chunk before) visible to its
    /// kernels: a fence wait alone does not, and submission order alone orders no memory.
    fn begin_chunk(&mut self) -> Result<()> {
        let device = &self.ctx.shared.device;
        // SAFETY: the pool belongs to this recording; the buffer is ended before submission.
        unsafe {
            self.cmd = device
                .allocate_command_buffers(
                    &vk::CommandBufferAllocateInfo::default()
                        .command_pool(self.res.command_pool)
                        .command_buffer_count(1),
                )
                .vk("vkAllocateCommandBuffers")?[0];
            device.begin_command_buffer(self.cmd, &vk::CommandBufferBeginInfo::default()).vk("vkBeginCommandBuffer")?;
            self.barrier(
                vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
                vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE,
                vk::PipelineStageFlags::COMPUTE_SHADER,
                vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE,
            );
        }
        self.written.clear();
        self.read.clear();
        self.chunk_flops = 0.0;
        self.chunk_dispatches = 0;
        Ok(())
    }

    /// Ends the chunk being recorded and starts the next once it holds its budget's worth.
    fn split_when_full(&mut self) -> Result<()> {
        if self.chunk_flops < self.budget.flops && self.chunk_dispatches < self.budget.dispatches {
            return Ok(());
        }
        // SAFETY: the command buffer is recording.
        unsafe { self.ctx.shared.device.end_command_buffer(self.cmd) }.vk("vkEndCommandBuffer")?;
        self.res.chunks.push(self.cmd);
        self.begin_chunk()
    }

    pub fn context(&self) -> &Context {
        &self.ctx
    }

    /// Buffers for an op's own temporaries: each goes back for reuse when the op drops its
    /// tensor, and the hazard tracking orders the reuse.
    pub fn scratch(&self) -> Arena {
        self.scratch.clone()
    }

    /// Records one dispatch of `kernel` over `groups` workgroups. Bindings are `reads` then
    /// `writes`, in the kernel's binding order; `push` fills its push constants.
    pub fn dispatch(
        &mut self,
        kernel: &Arc<Kernel>,
        reads: &[&Tensor],
        writes: &[&Tensor],
        push: &[u32],
        groups: [u32; 3],
    ) -> Result<()> {
        ensure(reads.len() + writes.len() == kernel.bindings as usize, || {
            format!("kernel `{}` takes {} bindings", kernel.name, kernel.bindings)
        })?;
        ensure(push.len() * 4 <= PUSH_BYTES as usize, || {
            format!("kernel `{}`: push constants too large", kernel.name)
        })?;
        let limit = self.ctx.choices().binding_limit;
        for t in reads.iter().chain(writes) {
            ensure(t.bytes() <= limit, || {
                format!(
                    "kernel `{}`: a {} tensor exceeds the {} storage binding limit",
                    kernel.name,
                    human_bytes(t.bytes()),
                    human_bytes(limit)
                )
            })?;
        }
        if groups.contains(&0) {
            return Ok(());
        }
        self.split_when_full()?;
        self.chunk_dispatches += 1;
        let hazard = reads.iter().any(|t| self.written.contains(&t.buf.raw))
            || writes.iter().any(|t| self.written.contains(&t.buf.raw) || self.read.contains(&t.buf.raw));
        let set = self.allocate_set(kernel)?;
        let timed = if self.profile { Some(self.query_slot()?) } else { None };
        let ctx = self.ctx.clone();
        let device = &ctx.shared.device;
        let operands: Vec<(&Tensor, vk::DescriptorType)> = reads
            .iter()
            .chain(writes)
            .enumerate()
            .map(|(i, &t)| (t, descriptor_type(kernel.variant, i as u32)))
            .collect();
        let mut views = Vec::new();
        for &(t, ty) in &operands {
            if ty == vk::DescriptorType::UNIFORM_TEXEL_BUFFER {
                let view = crate::texel_views::create(&ctx, t, crate::texel_views::Texels::of(kernel.variant))?;
                self.res.views.push(view);
                views.push([view]);
            }
        }
        let infos: Vec<[vk::DescriptorBufferInfo; 1]> = operands
            .iter()
            .map(|(t, _)| [vk::DescriptorBufferInfo { buffer: t.buf.raw, offset: t.offset, range: t.bytes().max(4) }])
            .collect();
        let mut texels = views.iter();
        let descriptor_writes: Vec<_> = operands
            .iter()
            .zip(&infos)
            .enumerate()
            .map(|(i, (&(_, ty), info))| {
                let write = vk::WriteDescriptorSet::default().dst_set(set).dst_binding(i as u32).descriptor_type(ty);
                match ty {
                    vk::DescriptorType::UNIFORM_TEXEL_BUFFER => write.texel_buffer_view(texels.next().unwrap()),
                    _ => write.buffer_info(info),
                }
            })
            .collect();
        // SAFETY: the command buffer is recording; every handle is kept alive by `res`.
        unsafe {
            device.update_descriptor_sets(&descriptor_writes, &[]);
            // A timed dispatch waits for those before it, so its stamps bracket it alone.
            if hazard || timed.is_some() {
                let compute = vk::PipelineStageFlags::COMPUTE_SHADER;
                self.barrier(
                    compute,
                    vk::AccessFlags::SHADER_WRITE,
                    compute,
                    vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE,
                );
                self.written.clear();
                self.read.clear();
            }
            if let Some((pool, q)) = timed {
                // Written once every earlier dispatch has finished (the barrier above).
                device.cmd_write_timestamp(self.cmd, vk::PipelineStageFlags::COMPUTE_SHADER, pool, q);
            }
            device.cmd_bind_pipeline(self.cmd, vk::PipelineBindPoint::COMPUTE, kernel.pipeline);
            device.cmd_bind_descriptor_sets(self.cmd, vk::PipelineBindPoint::COMPUTE, kernel.layout, 0, &[set], &[]);
            if !push.is_empty() {
                device.cmd_push_constants(
                    self.cmd,
                    kernel.layout,
                    vk::ShaderStageFlags::COMPUTE,
                    0,
                    bytemuck::cast_slice(push),
                );
            }
            self.dispatch_split(groups);
            if let Some((pool, q)) = timed {
                device.cmd_write_timestamp(self.cmd, vk::PipelineStageFlags::BOTTOM_OF_PIPE, pool, q + 1);
                self.res.labels.push(kernel.name);
            }
        }
        self.read.extend(reads.iter().map(|t| t.buf.raw));
        self.written.extend(writes.iter().map(|t| t.buf.raw));
        self.res.buffers.extend(reads.iter().chain(writes).map(|t| t.buf.clone()));
        if !self.res.kernels.iter().any(|k| Arc::ptr_eq(k, kernel)) {
            self.res.kernels.push(kernel.clone());
        }
        Ok(())
    }

    /// Records a grid of `groups` workgroups as dispatches of at most the workgroup limit per
    /// dimension, each based where the last ended (`vkCmdDispatchBase`), so kernels see the
    /// workgroup ids of the whole grid.
    ///
    /// SAFETY: the command buffer must be recording with a pipeline and its bindings bound.
    unsafe fn dispatch_split(&self, groups: [u32; 3]) {
        let limit = self.ctx.choices().workgroup_limit;
        let device = &self.ctx.shared.device;
        if groups.iter().zip(limit).all(|(&g, l)| g <= l) {
            return device.cmd_dispatch(self.cmd, groups[0], groups[1], groups[2]);
        }
        let starts =
            |d: usize| (0..groups[d]).step_by(limit[d] as usize).map(move |s| (s, (groups[d] - s).min(limit[d])));
        for (z, nz) in starts(2) {
            for (y, ny) in starts(1) {
                for (x, nx) in starts(0) {
                    device.cmd_dispatch_base(self.cmd, x, y, z, nx, ny, nz);
                }
            }
        }
    }

    /// SAFETY: the command buffer must be recording.
    unsafe fn barrier(
        &self,
        src_stage: vk::PipelineStageFlags,
        src: vk::AccessFlags,
        dst_stage: vk::PipelineStageFlags,
        dst: vk::AccessFlags,
    ) {
        memory_barrier(&self.ctx.shared.device, self.cmd, (src_stage, src), (dst_stage, dst));
    }

    fn allocate_set(&mut self, kernel: &Kernel) -> Result<vk::DescriptorSet> {
        let device = &self.ctx.shared.device;
        // SAFETY: pools and layouts are valid; pools are destroyed with the recording.
        unsafe {
            if self.sets_left == 0 {
                let sizes = [
                    vk::DescriptorPoolSize {
                        ty: vk::DescriptorType::STORAGE_BUFFER,
                        descriptor_count: SETS_PER_POOL * MAX_BINDINGS,
                    },
                    // A and B of the CPU products (pipeline::descriptor_type).
                    vk::DescriptorPoolSize {
                        ty: vk::DescriptorType::UNIFORM_TEXEL_BUFFER,
                        descriptor_count: 2 * SETS_PER_POOL,
                    },
                ];
                let pool = device
                    .create_descriptor_pool(
                        &vk::DescriptorPoolCreateInfo::default().max_sets(SETS_PER_POOL).pool_sizes(&sizes),
                        None,
                    )
                    .vk("vkCreateDescriptorPool")?;
                self.res.descriptor_pools.push(pool);
                self.sets_left = SETS_PER_POOL;
            }
            self.sets_left -= 1;
            let layouts = [kernel.set_layout];
            let pool = *self.res.descriptor_pools.last().unwrap();
            Ok(device
                .allocate_descriptor_sets(
                    &vk::DescriptorSetAllocateInfo::default().descriptor_pool(pool).set_layouts(&layouts),
                )
                .vk("vkAllocateDescriptorSets")?[0])
        }
    }

    /// The query pool and first of two query indices for the next timed dispatch.
    fn query_slot(&mut self) -> Result<(vk::QueryPool, u32)> {
        let used = 2 * self.res.labels.len() as u32;
        let within = used % QUERIES_PER_POOL;
        if within == 0 {
            let device = &self.ctx.shared.device;
            // SAFETY: plain creation; the reset is recorded before the pool's first use.
            unsafe {
                let pool = device
                    .create_query_pool(
                        &vk::QueryPoolCreateInfo::default()
                            .query_type(vk::QueryType::TIMESTAMP)
                            .query_count(QUERIES_PER_POOL),
                        None,
                    )
                    .vk("vkCreateQueryPool")?;
                device.cmd_reset_query_pool(self.cmd, pool, 0, QUERIES_PER_POOL);
                self.res.query_pools.push(pool);
            }
        }
        Ok((*self.res.query_pools.last().unwrap(), within))
    }

    /// Ends recording; results are visible to the host and to transfers once a run returns.
    pub fn finish(self) -> Result<Recording> {
        // SAFETY: the command buffer is recording.
        unsafe {
            self.barrier(
                vk::PipelineStageFlags::COMPUTE_SHADER,
                vk::AccessFlags::SHADER_WRITE,
                vk::PipelineStageFlags::HOST | vk::PipelineStageFlags::TRANSFER,
                vk::AccessFlags::HOST_READ | vk::AccessFlags::TRANSFER_READ,
            );
            self.ctx.shared.device.end_command_buffer(self.cmd).vk("vkEndCommandBuffer")?;
        }
        self.ctx.shared.host_stats.lock().unwrap().recording_seconds += self.started.elapsed().as_secs_f64();
        let mut res = self.res;
        res.chunks.push(self.cmd);
        crate::listing::note(res.kernels.iter().map(|k| k.variant));
        Ok(Recording::new(self.ctx, res, self.flops))
    }

    /// Counts the arithmetic of a matrix product just recorded (ops call it; see
    /// [`Recording::flops`]); it fills the chunk's budget too.
    pub(crate) fn count_flops(&mut self, flops: f64) {
        self.flops += flops;
        self.chunk_flops += flops;
    }
}

/// "3 MiB" from 1 MiB up, else "2048 bytes".
fn human_bytes(n: u64) -> String {
    if n >= 1 << 20 {
        format!("{} MiB", n >> 20)
    } else {
        format!("{n} bytes")
    }
}
