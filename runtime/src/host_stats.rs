//! Where a context's host time goes besides waiting for the device, for benchmarks to set
//! beside the device's own time.

/// Device tensors' buffers fresh from the driver and reused idle ones ([`crate::idle_buffers`]),
/// the host's time in the driver's allocation calls for every buffer (creating, binding and
/// freeing buffers and their memory; staging buffers included), and its time recording command
/// buffers (from `Recorder::new` to `finish`, allocations of the tensors made meanwhile
/// included).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HostStats {
    pub fresh: u64,
    pub fresh_bytes: u64,
    pub reused: u64,
    pub reused_bytes: u64,
    pub allocation_seconds: f64,
    pub recording_seconds: f64,
}

impl HostStats {
    /// What happened since `earlier`, a snapshot of the same context.
    pub fn since(&self, earlier: &HostStats) -> HostStats {
        HostStats {
            fresh: self.fresh - earlier.fresh,
            fresh_bytes: self.fresh_bytes - earlier.fresh_bytes,
            reused: self.reused - earlier.reused,
            reused_bytes: self.reused_bytes - earlier.reused_bytes,
            allocation_seconds: self.allocation_seconds - earlier.allocation_seconds,
            recording_seconds: self.recording_seconds - earlier.recording_seconds,
        }
    }
}
