//! Device buffers from gpu-allocator, with live and peak byte counts per context; buffers whose
//! tensors are gone wait idle for reuse (see [`crate::idle_buffers`]).

use crate::context::Shared;
use crate::error::{Error, Result, VkContext};
use crate::idle_buffers::Idle;
use ash::vk;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use gpu_allocator::MemoryLocation;
use std::mem::ManuallyDrop;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// Where a tensor's memory lives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Placement {
    /// Device-local memory: counted in the context's live and peak bytes and against
    /// `VKDIFF_MEMORY_BUDGET`.
    Device,
    /// Host memory the device reads over the bus (the same memory on lavapipe and integrated
    /// GPUs): for weights read once per prompt or style image, not once per step. Counted apart
    /// ([`crate::Context::host_bytes`]).
    Host,
}

/// What a buffer is for: its memory type and the figure it counts towards.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum BufferUse {
    Tensor(Placement),
    UploadStaging,
    DownloadStaging,
}

impl BufferUse {
    fn location(self) -> MemoryLocation {
        match self {
            BufferUse::Tensor(Placement::Device) => MemoryLocation::GpuOnly,
            // Host-cached system memory where the device has it, never the device-local
            // host-visible window (ReBAR) that CpuToGpu may pick.
            BufferUse::Tensor(Placement::Host) | BufferUse::DownloadStaging => MemoryLocation::GpuToCpu,
            BufferUse::UploadStaging => MemoryLocation::CpuToGpu,
        }
    }
}

/// One Vulkan buffer and its memory; freed (and uncounted) on drop.
pub struct Buffer {
    pub(crate) raw: vk::Buffer,
    pub(crate) size: u64,
    allocation: Mutex<Option<Allocation>>,
    /// Tensors count towards the context's memory figures; staging buffers do not.
    placement: Option<Placement>,
    pub(crate) shared: Arc<Shared>,
}

impl Buffer {
    pub(crate) fn new(shared: &Arc<Shared>, size: u64, use_: BufferUse, name: &str) -> Result<Arc<Buffer>> {
        // Whole words: fills (vkCmdFillBuffer) and vec4 kernels then cover an odd-length f16 tensor.
        let size = size.max(4).next_multiple_of(4);
        let limit = shared.choices.lock().unwrap().allocation_limit;
        if limit > 0 && size > limit {
            return Err(Error::Memory(format!(
                "`{name}` needs one {} MiB buffer, past this device's {} MiB maxMemoryAllocationSize; a smaller \
                image or batch needs less",
                size >> 20,
                limit >> 20
            )));
        }
        let placement = match use_ {
            BufferUse::Tensor(p) => Some(p),
            BufferUse::UploadStaging | BufferUse::DownloadStaging => None,
        };
        let counted = placement == Some(Placement::Device);
        if let Some(budget) = shared.memory_budget.filter(|_| counted) {
            let live = shared.live_bytes.load(Ordering::SeqCst);
            if live + size > budget {
                return Err(Error::Memory(format!(
                    "`{name}` needs {} MiB more with {} MiB in use, past VKDIFF_MEMORY_BUDGET ({} MiB)",
                    size.div_ceil(1 << 20),
                    live >> 20,
                    budget >> 20
                )));
            }
        }
        // A reused buffer may be larger than asked for, but not past the budget.
        let most =
            shared.memory_budget.map_or(u64::MAX, |b| b.saturating_sub(shared.live_bytes.load(Ordering::SeqCst)));
        let reused = if counted { shared.idle.lock().unwrap().take(size, most) } else { None };
        let (raw, allocation, size) = match reused {
            Some(idle) => {
                let mut stats = shared.host_stats.lock().unwrap();
                stats.reused += 1;
                stats.reused_bytes += idle.size;
                (idle.raw, idle.allocation, idle.size)
            }
            None => {
                if counted {
                    make_room(shared, size);
                }
                let start = Instant::now();
                let fresh = match allocate(shared, size, use_, name) {
                    Err(_) if shared.idle.lock().unwrap().bytes() > 0 => {
                        release_idle(shared);
                        allocate(shared, size, use_, name)
                    }
                    other => other,
                };
                let mut stats = shared.host_stats.lock().unwrap();
                stats.allocation_seconds += start.elapsed().as_secs_f64();
                let (raw, allocation) = fresh?;
                if counted {
                    stats.fresh += 1;
                    stats.fresh_bytes += size;
                }
                (raw, allocation, size)
            }
        };
        match placement {
            Some(Placement::Device) => {
                let live = shared.live_bytes.fetch_add(size, Ordering::SeqCst) + size;
                shared.peak_bytes.fetch_max(live, Ordering::SeqCst);
                shared.most_live.fetch_max(live, Ordering::SeqCst);
            }
            Some(Placement::Host) => {
                shared.host_bytes.fetch_add(size, Ordering::SeqCst);
            }
            None => {}
        }
        Ok(Arc::new(Buffer { raw, size, allocation: Mutex::new(Some(allocation)), placement, shared: shared.clone() }))
    }

    /// Runs `f` on the buffer's host mapping, if the memory is host-visible (always on lavapipe)
    /// and, under `VKDIFF_GPU_PATHS=1`, not device-only memory (which then goes through staging).
    pub(crate) fn with_mapped<R>(&self, f: impl FnOnce(&mut [u8]) -> R) -> Option<R> {
        if self.placement == Some(Placement::Device) && self.shared.choices.lock().unwrap().gpu_paths {
            return None;
        }
        let mut guard = self.allocation.lock().unwrap();
        guard.as_mut()?.mapped_slice_mut().map(f)
    }
}

impl Drop for Buffer {
    fn drop(&mut self) {
        if self.shared.hung.load(Ordering::SeqCst) {
            return; // a timed-out submission may still use it; the process ends anyway
        }
        match self.placement {
            Some(Placement::Device) => self.shared.live_bytes.fetch_sub(self.size, Ordering::SeqCst),
            Some(Placement::Host) => self.shared.host_bytes.fetch_sub(self.size, Ordering::SeqCst),
            None => 0,
        };
        let Some(allocation) = self.allocation.lock().unwrap().take() else { return };
        let idle = Idle { raw: self.raw, allocation, size: self.size };
        // Recordings keep their buffers alive, so no pending work uses this one.
        if self.placement == Some(Placement::Device) && self.shared.keep_idle {
            self.shared.idle.lock().unwrap().put(idle);
        } else {
            free(&self.shared, vec![idle]);
        }
    }
}

/// A new buffer of `size` bytes and its memory, from the driver.
fn allocate(shared: &Shared, size: u64, use_: BufferUse, name: &str) -> Result<(vk::Buffer, Allocation)> {
    let mut usage =
        vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::TRANSFER_SRC | vk::BufferUsageFlags::TRANSFER_DST;
    // The CPU GEMM may read A and B through texel views of any buffer (KernelPlan::texel_reads).
    if shared.info.reads_texels() {
        usage |= vk::BufferUsageFlags::UNIFORM_TEXEL_BUFFER;
    }
    let info = vk::BufferCreateInfo::default().size(size).usage(usage).sharing_mode(vk::SharingMode::EXCLUSIVE);
    let device = &shared.device;
    // SAFETY: valid device and create info.
    let raw = unsafe { device.create_buffer(&info, None) }.vk("vkCreateBuffer")?;
    // SAFETY: raw was just created on this device.
    let requirements = unsafe { device.get_buffer_memory_requirements(raw) };
    let allocation = shared
        .allocator
        .lock()
        .unwrap()
        .allocate(&AllocationCreateDesc {
            name,
            requirements,
            location: use_.location(),
            linear: true,
            allocation_scheme: AllocationScheme::GpuAllocatorManaged,
        })
        .map_err(|e| {
            // SAFETY: the buffer has no memory bound and is not in use.
            unsafe { device.destroy_buffer(raw, None) };
            Error::Memory(format!("{e} (asking for {} MiB for `{name}`)", size >> 20))
        })?;
    // SAFETY: the allocation satisfies the buffer's requirements and is unused.
    unsafe { device.bind_buffer_memory(raw, allocation.memory(), allocation.offset()) }.vk("vkBindBufferMemory")?;
    Ok((raw, allocation))
}

/// Gives back the oldest idle buffers that would take the process, with `size` bytes more,
/// past the most its tensors have held at once.
fn make_room(shared: &Shared, size: u64) {
    let live = shared.live_bytes.load(Ordering::SeqCst);
    let keep = idle_to_keep(live, size, shared.most_live.load(Ordering::SeqCst));
    let evicted = shared.idle.lock().unwrap().evict_to(keep);
    free(shared, evicted);
}

/// The idle bytes that fit beside `live` bytes and `size` more under the most ever live (or the
/// new total, where it passes that).
fn idle_to_keep(live: u64, size: u64, most_live: u64) -> u64 {
    most_live.saturating_sub(live + size)
}

/// Gives every idle buffer back to the driver.
pub(crate) fn release_idle(shared: &Shared) {
    let idle = shared.idle.lock().unwrap().evict_to(0);
    free(shared, idle);
}

fn free(shared: &Shared, buffers: Vec<Idle>) {
    if buffers.is_empty() {
        return;
    }
    let start = Instant::now();
    for idle in buffers {
        let _ = shared.allocator.lock().unwrap().free(idle.allocation);
        // SAFETY: no tensor or recording holds the buffer any more.
        unsafe { shared.device.destroy_buffer(idle.raw, None) };
    }
    shared.host_stats.lock().unwrap().allocation_seconds += start.elapsed().as_secs_f64();
}

impl Drop for Shared {
    fn drop(&mut self) {
        if self.hung.load(Ordering::SeqCst) {
            return; // the device may still run work on these objects; the process ends anyway
        }
        // SAFETY: every buffer and recording holds an Arc<Shared>, so none is alive any more.
        unsafe {
            let _ = self.device.device_wait_idle();
            release_idle(self);
            self.pipelines.destroy(&self.device);
            ManuallyDrop::drop(&mut self.allocator);
            self.device.destroy_device(None);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::idle_to_keep;

    #[test]
    fn idle_buffers_never_take_the_process_past_its_peak() {
        assert_eq!(idle_to_keep(500, 100, 1000), 400);
        assert_eq!(idle_to_keep(500, 500, 1000), 0);
        assert_eq!(idle_to_keep(500, 700, 1000), 0, "a new peak keeps none");
        assert_eq!(idle_to_keep(0, 0, 1000), 1000);
    }
}
