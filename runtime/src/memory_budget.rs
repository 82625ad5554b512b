//! How much device memory this process may still take: `VKDIFF_MEMORY_BUDGET`
//! ([`crate::Settings::memory_budget`]) where set (and
//! then enforced: an allocation past it fails); on a CPU device (lavapipe), whose memory is the
//! host's whatever heap it reports (Mesa 22.3: 2 GiB), the host memory still available (and the
//! cgroup's limit, in a container); else `VK_EXT_memory_budget`'s heap budget less the heap's
//! use, else the device-local heap less vkdiff's own live buffers.

use crate::context::{Context, Shared};
use crate::device::DeviceKind;
use ash::vk;
use std::sync::atomic::Ordering;

/// The memory a plan may count on, and where the figure comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MemoryRoom {
    /// Bytes still free to this process.
    pub free: u64,
    /// The whole budget they are part of.
    pub budget: u64,
    pub source: &'static str,
}

impl Context {
    /// The device memory this process may still allocate (see the module's comment). Idle
    /// buffers count as free: they are given back before an allocation would not fit.
    pub fn memory_room(&self) -> MemoryRoom {
        let shared = &self.shared;
        let live = shared.live_bytes.load(Ordering::SeqCst);
        if let Some(budget) = shared.memory_budget {
            return MemoryRoom { free: budget.saturating_sub(live), budget, source: "VKDIFF_MEMORY_BUDGET" };
        }
        if shared.info.kind == DeviceKind::Cpu {
            if let Some((total, available)) = host_memory(&|path| std::fs::read_to_string(path).ok()) {
                // Idle buffers are host memory this process would give back first.
                let idle = shared.idle.lock().unwrap().bytes();
                return MemoryRoom { free: available + idle, budget: total, source: HOST_MEMORY };
            }
        }
        if let Some((total, used)) = device_heap(shared) {
            let idle = shared.idle.lock().unwrap().bytes();
            let free = total.saturating_sub(used.saturating_sub(idle));
            return MemoryRoom { free, budget: total, source: "VK_EXT_memory_budget" };
        }
        let heap = shared.info.device_local_bytes;
        MemoryRoom { free: heap.saturating_sub(live), budget: heap, source: "the device-local heap" }
    }
}

/// The source a CPU device's room comes from.
pub const HOST_MEMORY: &str = "the host's available memory (a CPU device)";

/// The host's (total, available) memory: /proc/meminfo's MemTotal and MemAvailable, within the
/// cgroup v2 limit of this process's container where one is set. `read` reads a file.
pub(crate) fn host_memory(read: &dyn Fn(&str) -> Option<String>) -> Option<(u64, u64)> {
    let meminfo = read("/proc/meminfo")?;
    let kib = |key: &str| -> Option<u64> {
        let line = meminfo.lines().find(|l| l.starts_with(key))?;
        Some(line[key.len()..].trim().trim_end_matches("kB").trim().parse::<u64>().ok()? * 1024)
    };
    let (mut total, mut available) = (kib("MemTotal:")?, kib("MemAvailable:")?);
    let number = |path: &str| read(path).and_then(|t| t.trim().parse::<u64>().ok());
    if let (Some(max), Some(current)) = (number("/sys/fs/cgroup/memory.max"), number("/sys/fs/cgroup/memory.current")) {
        total = total.min(max);
        available = available.min(max.saturating_sub(current));
    }
    Some((total, available))
}

/// `VK_EXT_memory_budget`'s (budget, usage) of the largest device-local heap, where the device
/// reports them.
fn device_heap(shared: &Shared) -> Option<(u64, u64)> {
    if !shared.memory_budget_extension {
        return None;
    }
    let mut budget = vk::PhysicalDeviceMemoryBudgetPropertiesEXT::default();
    let mut props = vk::PhysicalDeviceMemoryProperties2::default().push_next(&mut budget);
    // SAFETY: the physical device belongs to the live instance; the struct outlives the call.
    unsafe { shared.vulkan.raw.get_physical_device_memory_properties2(shared.physical_device, &mut props) };
    let heaps = props.memory_properties.memory_heaps;
    let count = props.memory_properties.memory_heap_count as usize;
    let heap = (0..count)
        .filter(|&i| heaps[i].flags.contains(vk::MemoryHeapFlags::DEVICE_LOCAL))
        .max_by_key(|&i| heaps[i].size)?;
    Some((budget.heap_budget[heap], budget.heap_usage[heap]))
}

#[cfg(test)]
mod tests {
    use super::host_memory;

    #[test]
    fn host_memory_is_meminfos_within_the_cgroups_limit() {
        let meminfo = "MemTotal:       24576000 kB\nMemFree:         1000 kB\nMemAvailable:   20480000 kB\n";
        let files = |cgroup: Option<(&'static str, &'static str)>| {
            move |path: &str| match (path, cgroup) {
                ("/proc/meminfo", _) => Some(meminfo.to_string()),
                ("/sys/fs/cgroup/memory.max", Some((max, _))) => Some(max.to_string()),
                ("/sys/fs/cgroup/memory.current", Some((_, current))) => Some(current.to_string()),
                _ => None,
            }
        };
        assert_eq!(host_memory(&files(None)), Some((24_576_000 * 1024, 20_480_000 * 1024)));
        // A container limited to 8 GiB that holds 2 GiB.
        let limited = host_memory(&files(Some(("8589934592\n", "2147483648\n"))));
        assert_eq!(limited, Some((8 << 30, 6 << 30)));
        // No limit set.
        assert_eq!(host_memory(&files(Some(("max\n", "2147483648\n")))), Some((24_576_000 * 1024, 20_480_000 * 1024)));
        assert_eq!(host_memory(&|_| None), None);
    }
}
