//! Device buffers whose tensors are gone, kept for later tensors of about the same size, as
//! PyTorch keeps CUDA memory in its caching allocator. A network's forward asks for the same
//! sizes every time it runs (an image's VAE decode: hundreds of MiB to several GiB), and getting
//! device memory from the driver and giving it back costs far more than reusing a buffer: the
//! driver maps (and clears) every new allocation. Idle buffers are given back oldest first
//! before a new allocation would take the process past the most its tensors ever held at once,
//! so the cache never holds more memory than running without it did at its peak (`memory.rs`);
//! `VKDIFF_BUFFER_CACHE=0` gives every buffer back as its tensors go.

use ash::vk;
use gpu_allocator::vulkan::Allocation;
use std::collections::VecDeque;

/// A buffer no tensor uses, with its memory.
pub(crate) struct Idle {
    pub raw: vk::Buffer,
    pub allocation: Allocation,
    pub size: u64,
}

#[derive(Default)]
pub(crate) struct IdleBuffers {
    /// Oldest first.
    entries: VecDeque<Idle>,
    bytes: u64,
}

impl IdleBuffers {
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// The smallest idle buffer of `size` bytes up to a quarter more (the arena's size classes
    /// are a quarter apart, so the class of `size` and no larger one), and at most `most`.
    pub fn take(&mut self, size: u64, most: u64) -> Option<Idle> {
        let fits = |b: &Idle| b.size >= size && b.size <= (size + size / 4).min(most);
        let (i, _) = self.entries.iter().enumerate().filter(|(_, b)| fits(b)).min_by_key(|(_, b)| b.size)?;
        let idle = self.entries.remove(i)?;
        self.bytes -= idle.size;
        Some(idle)
    }

    pub fn put(&mut self, idle: Idle) {
        self.bytes += idle.size;
        self.entries.push_back(idle);
    }

    /// The oldest buffers past `keep` bytes, for the caller to free.
    pub fn evict_to(&mut self, keep: u64) -> Vec<Idle> {
        let mut evicted = Vec::new();
        while self.bytes > keep {
            let oldest = self.entries.pop_front().expect("bytes count entries");
            self.bytes -= oldest.size;
            evicted.push(oldest);
        }
        evicted
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
        let mut cache = IdleBuffers::default();
        for size in [1000, 1300, 1200, 4000] {
            cache.put(idle(size));
        }
        assert_eq!(cache.bytes(), 7500);
        let take = |cache: &mut IdleBuffers, size, most| cache.take(size, most).map(|b| b.size);
        assert_eq!(take(&mut cache, 1000, u64::MAX), Some(1000));
        assert_eq!(take(&mut cache, 1000, 1199), None, "1200 is past the most asked for");
        assert_eq!(take(&mut cache, 1000, u64::MAX), Some(1200), "1300 is more than a quarter past 1000");
        assert_eq!(take(&mut cache, 1000, u64::MAX), None);
        assert_eq!(take(&mut cache, 5000, u64::MAX), None, "never a smaller buffer");
        assert_eq!(take(&mut cache, 3300, u64::MAX), Some(4000));
        assert_eq!(cache.bytes(), 1300);
    }

    #[test]
    fn gives_back_the_oldest_first() {
        let mut cache = IdleBuffers::default();
        for size in [400, 300, 500] {
            cache.put(idle(size));
        }
        assert!(cache.evict_to(1200).is_empty());
        assert_eq!(sizes(&cache.evict_to(1000)), [400]);
        assert_eq!(cache.bytes(), 800);
        assert_eq!(sizes(&cache.evict_to(0)), [300, 500]);
        assert_eq!(cache.bytes(), 0);
    }
}
