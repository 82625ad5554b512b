//! Recycled device buffers for the intermediate tensors of a recorded network.
//!
//! A network forward allocates hundreds of short-lived tensors. Recording keeps every buffer it
//! touched alive, so without reuse a forward would hold all of them at once. An [`Arena`] hands a
//! buffer back to its free list when the last [`Tensor`] over it is dropped, and the next
//! allocation of a similar size takes it; the recorder's hazard tracking orders the reuse with a
//! barrier. Tensors the caller keeps (inputs, outputs) must not come from the arena of a recording
//! that is replayed after them, or a replay would overwrite them: give each recording its own.

use crate::context::Context;
use crate::error::Result;
use crate::memory::{Buffer, BufferUse, Placement};
use crate::tensor::{dtype_size, Dtype, Tensor};
use std::sync::{Arc, Mutex};

/// A pool of device buffers; clones share it.
#[derive(Clone)]
pub struct Arena {
    inner: Arc<Inner>,
}

struct Inner {
    ctx: Context,
    free: Mutex<Vec<Arc<Buffer>>>,
}

/// Returns its buffer to the arena when the last tensor holding it goes.
pub(crate) struct Lease {
    buf: Arc<Buffer>,
    arena: Arc<Inner>,
}

impl Drop for Lease {
    fn drop(&mut self) {
        self.arena.free.lock().unwrap().push(self.buf.clone());
    }
}

/// Allocation sizes are rounded up to one of four steps per power of two, so buffers fit later
/// requests of nearby sizes.
fn size_class(bytes: u64) -> u64 {
    let bytes = bytes.max(256);
    let step = (1u64 << (63 - bytes.leading_zeros())) / 4;
    bytes.div_ceil(step) * step
}

impl Arena {
    pub fn new(ctx: &Context) -> Arena {
        Arena { inner: Arc::new(Inner { ctx: ctx.clone(), free: Mutex::new(Vec::new()) }) }
    }

    /// An uninitialised tensor: the smallest free buffer that holds it and is at most twice its
    /// size, else a new one.
    pub fn tensor(&self, shape: &[usize], dtype: Dtype) -> Result<Tensor> {
        let bytes = (shape.iter().product::<usize>() * dtype_size(dtype)) as u64;
        let mut free = self.inner.free.lock().unwrap();
        let best = free
            .iter()
            .enumerate()
            .filter(|(_, b)| b.size >= bytes && b.size <= 2 * size_class(bytes))
            .min_by_key(|(_, b)| b.size)
            .map(|(i, _)| i);
        let buf = match best {
            Some(i) => free.swap_remove(i),
            None => Buffer::new(
                &self.inner.ctx.shared,
                size_class(bytes),
                BufferUse::Tensor(Placement::Device),
                "arena tensor",
            )?,
        };
        drop(free);
        let lease = Arc::new(Lease { buf: buf.clone(), arena: self.inner.clone() });
        Ok(Tensor::leased(buf, lease, shape, dtype))
    }

    /// Bytes held by the arena's idle buffers.
    pub fn idle_bytes(&self) -> u64 {
        self.inner.free.lock().unwrap().iter().map(|b| b.size).sum()
    }
}
