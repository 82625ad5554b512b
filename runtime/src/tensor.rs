//! `Tensor`: a shape and a storage dtype over a range of a device buffer.

use crate::arena::Lease;
use crate::context::Context;
use crate::error::{ensure, Error, Result};
use crate::memory::{Buffer, BufferUse, Placement};
use crate::submit::submit_once;
use ash::vk;
use half::f16;
use std::sync::Arc;
pub use vkdiff_kernels::Dtype;

/// Deterministic values uniform in [-1, 1) (xorshift64*, one stream per `seed`): the data of the
/// tests and of the matrix units' trial, which no fragment layout could reproduce by accident.
pub fn uniform_values(n: usize, seed: u64) -> Vec<f32> {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    (0..n)
        .map(|_| {
            s ^= s >> 12;
            s ^= s << 25;
            s ^= s >> 27;
            let x = s.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 40;
            (x as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
        })
        .collect()
}

/// Bytes per element of a storage dtype.
pub fn dtype_size(dtype: Dtype) -> usize {
    match dtype {
        Dtype::F32 => 4,
        Dtype::F16 => 2,
    }
}

/// A dense, row-major tensor in device memory. Clones and views share the buffer.
#[derive(Clone)]
pub struct Tensor {
    pub(crate) buf: Arc<Buffer>,
    pub(crate) offset: u64,
    shape: Vec<usize>,
    dtype: Dtype,
    /// Set for arena tensors: hands the buffer back when the last view goes.
    _lease: Option<Arc<Lease>>,
}

impl std::fmt::Debug for Tensor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Tensor({:?}, {:?}, byte offset {})", self.shape, self.dtype, self.offset)
    }
}

impl Tensor {
    fn owned(buf: Arc<Buffer>, shape: &[usize], dtype: Dtype) -> Tensor {
        Tensor { buf, offset: 0, shape: shape.to_vec(), dtype, _lease: None }
    }

    pub(crate) fn leased(buf: Arc<Buffer>, lease: Arc<Lease>, shape: &[usize], dtype: Dtype) -> Tensor {
        Tensor { buf, offset: 0, shape: shape.to_vec(), dtype, _lease: Some(lease) }
    }

    pub fn shape(&self) -> &[usize] {
        &self.shape
    }

    pub fn dtype(&self) -> Dtype {
        self.dtype
    }

    /// The context whose device holds the tensor.
    pub fn context(&self) -> Context {
        Context { shared: self.buf.shared.clone() }
    }

    pub fn numel(&self) -> usize {
        self.shape.iter().product()
    }

    pub fn bytes(&self) -> u64 {
        (self.numel() * dtype_size(self.dtype)) as u64
    }

    /// The same elements under another shape.
    pub fn reshape(&self, shape: &[usize]) -> Result<Tensor> {
        let n: usize = shape.iter().product();
        ensure(n == self.numel(), || format!("cannot reshape {:?} to {shape:?}", self.shape))?;
        Ok(Tensor { shape: shape.to_vec(), ..self.clone() })
    }

    /// Rows `start..start + len` of the first dimension, without copying. The start must fall on
    /// the device's storage-binding alignment, as kernels bind views directly.
    pub fn narrow(&self, start: usize, len: usize) -> Result<Tensor> {
        let rows = *self.shape.first().unwrap_or(&1);
        ensure(start + len <= rows, || format!("rows {start}..{} out of range for {:?}", start + len, self.shape))?;
        let row_bytes = (self.numel() / rows.max(1) * dtype_size(self.dtype)) as u64;
        let offset = self.offset + start as u64 * row_bytes;
        let align = self.buf.shared.info.binding_alignment();
        ensure(offset.is_multiple_of(align), || {
            format!("view at byte {offset} breaks the device's {align}-byte binding alignment")
        })?;
        let mut shape = self.shape.clone();
        shape[0] = len;
        Ok(Tensor { offset, shape, ..self.clone() })
    }

    /// Overwrites the tensor with `data` (converted to the storage dtype).
    pub fn write(&self, data: &[f32]) -> Result<()> {
        ensure(data.len() == self.numel(), || {
            format!("writing {} values into a tensor of shape {:?}", data.len(), self.shape)
        })?;
        self.write_bytes(&encode(data, self.dtype))
    }

    fn write_bytes(&self, bytes: &[u8]) -> Result<()> {
        let (offset, len) = (self.offset as usize, bytes.len());
        if self.buf.with_mapped(|m| m[offset..offset + len].copy_from_slice(bytes)).is_some() {
            return Ok(());
        }
        let staging = Buffer::new(&self.buf.shared, len as u64, BufferUse::UploadStaging, "upload staging")?;
        staging.with_mapped(|m| m[..len].copy_from_slice(bytes)).ok_or_else(not_host_visible)?;
        copy(&staging, 0, &self.buf, self.offset, len as u64)
    }

    /// The tensor's values as f32.
    pub fn download(&self) -> Result<Vec<f32>> {
        let len = self.bytes() as usize;
        let offset = self.offset as usize;
        if let Some(bytes) = self.buf.with_mapped(|m| m[offset..offset + len].to_vec()) {
            return Ok(decode(&bytes, self.dtype));
        }
        let staging = Buffer::new(&self.buf.shared, len as u64, BufferUse::DownloadStaging, "download staging")?;
        copy(&self.buf, self.offset, &staging, 0, len as u64)?;
        staging.with_mapped(|m| decode(&m[..len], self.dtype)).ok_or_else(not_host_visible)
    }
}

fn not_host_visible() -> Error {
    Error::Memory("staging buffer is not host-visible".into())
}

/// Copies `size` bytes between buffers of one context on the device, waiting for it.
fn copy(src: &Buffer, src_offset: u64, dst: &Buffer, dst_offset: u64, size: u64) -> Result<()> {
    let ctx = Context { shared: src.shared.clone() };
    submit_once(&ctx, |device, cmd| {
        let region = [vk::BufferCopy { src_offset, dst_offset, size }];
        // SAFETY: both buffers are alive and large enough.
        unsafe { device.cmd_copy_buffer(cmd, src.raw, dst.raw, &region) };
    })
}

fn encode(data: &[f32], dtype: Dtype) -> Vec<u8> {
    match dtype {
        Dtype::F32 => bytemuck::cast_slice(data).to_vec(),
        Dtype::F16 => data.iter().flat_map(|&x| f16::from_f32(x).to_le_bytes()).collect(),
    }
}

fn decode(bytes: &[u8], dtype: Dtype) -> Vec<f32> {
    match dtype {
        Dtype::F32 => bytes.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect(),
        Dtype::F16 => bytes.chunks_exact(2).map(|c| f16::from_le_bytes([c[0], c[1]]).to_f32()).collect(),
    }
}

impl Context {
    /// A zero-filled tensor.
    pub fn zeros(&self, shape: &[usize], dtype: Dtype) -> Result<Tensor> {
        let numel: usize = shape.iter().product();
        let size = (numel * dtype_size(dtype)) as u64;
        let buf = Buffer::new(&self.shared, size, BufferUse::Tensor(Placement::Device), "tensor")?;
        if buf.with_mapped(|m| m.fill(0)).is_none() {
            submit_once(self, |device, cmd| {
                // SAFETY: the buffer is alive; fill size is whole buffer.
                unsafe { device.cmd_fill_buffer(cmd, buf.raw, 0, vk::WHOLE_SIZE, 0) };
            })?;
        }
        Ok(Tensor::owned(buf, shape, dtype))
    }

    /// A tensor holding `data` (row-major, converted to `dtype`).
    pub fn upload(&self, shape: &[usize], dtype: Dtype, data: &[f32]) -> Result<Tensor> {
        self.upload_to(Placement::Device, shape, dtype, data)
    }

    /// [`Context::upload`] into memory placed as `placement` says.
    pub fn upload_to(&self, placement: Placement, shape: &[usize], dtype: Dtype, data: &[f32]) -> Result<Tensor> {
        let numel: usize = shape.iter().product();
        ensure(numel == data.len(), || format!("{} values for shape {shape:?}", data.len()))?;
        self.upload_bytes_to(placement, shape, dtype, &encode(data, dtype))
    }

    /// A tensor holding `bytes`, already encoded in `dtype` (weights streamed from a file).
    pub fn upload_bytes(&self, shape: &[usize], dtype: Dtype, bytes: &[u8]) -> Result<Tensor> {
        self.upload_bytes_to(Placement::Device, shape, dtype, bytes)
    }

    /// [`Context::upload_bytes`] into memory placed as `placement` says.
    pub fn upload_bytes_to(&self, placement: Placement, shape: &[usize], dtype: Dtype, bytes: &[u8]) -> Result<Tensor> {
        let numel: usize = shape.iter().product();
        ensure(numel * dtype_size(dtype) == bytes.len(), || {
            format!("{} bytes for {dtype:?} shape {shape:?}", bytes.len())
        })?;
        let buf = Buffer::new(&self.shared, bytes.len() as u64, BufferUse::Tensor(placement), "tensor")?;
        let t = Tensor::owned(buf, shape, dtype);
        t.write_bytes(bytes)?;
        Ok(t)
    }
}

#[cfg(test)]
mod tests {
    use super::uniform_values;

    #[test]
    fn uniform_values_span_the_unit_interval_and_differ_by_seed() {
        let a = uniform_values(4096, 1);
        assert!(a.iter().all(|v| (-1.0..1.0).contains(v)));
        assert!(a.iter().any(|&v| v < -0.9) && a.iter().any(|&v| v > 0.9));
        assert_eq!(a[..8], uniform_values(8, 1)[..]);
        assert_ne!(a[..8], uniform_values(8, 2)[..]);
    }
}
