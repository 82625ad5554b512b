//! Device buffers whose tensors are gone, kept for later tensors of about the same size, as
//! PyTorch keeps CUDA memory in its caching allocator. A network's forward asks for the same
//! sizes every time it runs (an image's VAE decode: hundreds of MiB to several GiB), and getting
//! device memory from the driver and giving it back costs far more than reusing a buffer: the
//! driver maps (and clears) every new allocation. Idle buffers are given back oldest first past a
//! cap, and all of them before an allocation would pass the memory budget
//! (`memory.rs`); `VKDIFF_BUFFER_CACHE=0` gives every buffer back as its tensors go.

use crate::error::{Error, Result};
use ash::vk;
use gpu_allocator::vulkan::Allocation;
use std::collections::VecDeque;

/// A buffer no tensor uses, with its memory.
pub(crate) struct Idle {
    pub raw: vk::Buffer,
    pub allocation: Allocation,
    pub size: u64,
}

/// What buffers came from: fresh from the driver or reused, and the host's time in the driver's
/// allocation calls (creating, binding and freeing buffers and their memory).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AllocationStats {
    pub fresh: u64,
    pub fresh_bytes: u64,
    pub reused: u64,
    pub reused_bytes: u64,
    pub driver_seconds: f64,
}

impl AllocationStats {
    /// What happened since `earlier`, a snapshot of the same context.
    pub fn since(&self, earlier: &AllocationStats) -> AllocationStats {
        AllocationStats {
            fresh: self.fresh - earlier.fresh,
            fresh_bytes: self.fresh_bytes - earlier.fresh_bytes,
            reused: self.reused - earlier.reused,
            reused_bytes: self.reused_bytes - earlier.reused_bytes,
            driver_seconds: self.driver_seconds - earlier.driver_seconds,
        }
    }
}

pub(crate) struct IdleBuffers {
    /// Oldest first.
    entries: VecDeque<Idle>,
    bytes: u64,
    /// The most bytes kept idle; 0 keeps none.
    cap: u64,
}

impl IdleBuffers {
    pub fn new(cap: u64) -> IdleBuffers {
        IdleBuffers { entries: VecDeque::new(), bytes: 0, cap }
    }

    /// `VKDIFF_BUFFER_CACHE`: on (the default) keeps up to a quarter of `memory` idle.
    pub fn from_setting(value: Option<&str>, memory: u64) -> Result<IdleBuffers> {
        let on = match value.map(|v| v.trim().to_ascii_lowercase()) {
            None => true,
            Some(v) => match v.as_str() {
                "" | "1" | "true" | "yes" | "on" => true,
                "0" | "false" | "no" | "off" => false,
                _ => {
                    return Err(Error::BadSetting(format!(
                        "VKDIFF_BUFFER_CACHE={}: use 1 (keep freed device buffers for reuse, the default) or 0 \
                         (give each back to the driver at once)",
                        value.unwrap_or_default()
                    )))
                }
            },
        };
        Ok(IdleBuffers::new(if on { memory / 4 } else { 0 }))
    }

    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// The smallest idle buffer of `size` bytes up to a quarter more (the arena's size classes
    /// are a quarter apart, so the class of `size` and no larger one).
    pub fn take(&mut self, size: u64) -> Option<Idle> {
        let fits = |b: &Idle| b.size >= size && b.size <= size + size / 4;
        let (i, _) = self.entries.iter().enumerate().filter(|(_, b)| fits(b)).min_by_key(|(_, b)| b.size)?;
        let idle = self.entries.remove(i)?;
        self.bytes -= idle.size;
        Some(idle)
    }

    /// Keeps `idle`; returns what now passes the cap (oldest first), or `idle` itself where it
    /// alone does, for the caller to free.
    pub fn put(&mut self, idle: Idle) -> Vec<Idle> {
        if idle.size > self.cap {
            return vec![idle];
        }
        self.bytes += idle.size;
        self.entries.push_back(idle);
        let mut evicted = Vec::new();
        while self.bytes > self.cap {
            let oldest = self.entries.pop_front().expect("bytes count entries");
            self.bytes -= oldest.size;
            evicted.push(oldest);
        }
        evicted
    }

    /// Every idle buffer, for the caller to free.
    pub fn drain(&mut self) -> Vec<Idle> {
        self.bytes = 0;
        self.entries.drain(..).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn idle(size: u64) -> Idle {
        Idle { raw: vk::Buffer::null(), allocation: Allocation::default(), size }
    }

    fn sizes(buffers: &[Idle]) -> Vec<u64> {
        buffers.iter().map(|b| b.size).collect()
    }

    #[test]
    fn takes_the_smallest_within_a_quarter() {
        let mut cache = IdleBuffers::new(1 << 20);
        for size in [1000, 1300, 1200, 4000] {
            assert!(cache.put(idle(size)).is_empty());
        }
        assert_eq!(cache.bytes(), 7500);
        assert_eq!(cache.take(1000).map(|b| b.size), Some(1000));
        assert_eq!(cache.take(1000).map(|b| b.size), Some(1200), "1300 is more than a quarter past 1000");
        assert!(cache.take(1000).is_none());
        assert!(cache.take(5000).is_none(), "never a smaller buffer");
        assert_eq!(cache.take(3300).map(|b| b.size), Some(4000));
        assert_eq!(cache.bytes(), 1300);
    }

    #[test]
    fn gives_back_the_oldest_past_the_cap() {
        let mut cache = IdleBuffers::new(1000);
        assert!(cache.put(idle(400)).is_empty());
        assert!(cache.put(idle(300)).is_empty());
        assert_eq!(sizes(&cache.put(idle(500))), [400]);
        assert_eq!(sizes(&cache.put(idle(1001))), [1001], "larger than the cap alone");
        assert_eq!(cache.bytes(), 800);
        assert_eq!(sizes(&cache.drain()), [300, 500]);
        assert_eq!(cache.bytes(), 0);
    }

    #[test]
    fn the_setting_switches_reuse() {
        let cap = |v: Option<&str>| IdleBuffers::from_setting(v, 8 << 30).map(|c| c.cap);
        assert_eq!(cap(None).unwrap(), 2 << 30);
        assert_eq!(cap(Some("on")).unwrap(), 2 << 30);
        for off in ["0", "off", "False", " no "] {
            assert_eq!(cap(Some(off)).unwrap(), 0, "{off}");
        }
        let err = cap(Some("sometimes")).unwrap_err().to_string();
        assert!(err.starts_with("VKDIFF_BUFFER_CACHE=sometimes: use 1"), "{err}");
        let mut off = IdleBuffers::from_setting(Some("0"), 8 << 30).unwrap();
        assert_eq!(sizes(&off.put(idle(4))), [4]);
    }
}
