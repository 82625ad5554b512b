//! Typed operations: each checks its tensors, picks the kernel variant for the device and shape,
//! and records one dispatch. Networks are compositions of these.

mod attention;
mod attention_cm2;
mod attention_products;
mod bands;
mod ceiling;
mod conv;
mod conv_cm2;
mod conv_padded;
mod coop_tile;
mod copy_heads;
mod elementwise;
mod gemm;
mod gemm_family;
mod linear_cm2;
mod matrix2_probes;
mod norm;
mod pool;
mod winograd;

pub use attention::{attention, AttentionLayout};
pub use attention_cm2::attention_cm2;
pub use ceiling::{matrix_ceiling, MatrixCeiling};
pub use conv::{conv2d, oihw_to_ohwi, ConvParams, Padding};
pub use conv_cm2::conv2d_cm2;
pub use copy_heads::{copy_heads, HeadSpan};
pub use elementwise::{
    add, binary, concat_channels, copy_into_channels, geglu, mul, timestep_embedding, unary, upsample_nearest2x,
    BinaryOp, TimestepEmbedding, UnaryOp,
};
pub use gemm::{linear, linear_geglu, matmul, Matmul, GEGLU_COLUMNS};
pub(crate) use gemm_family::SMALL_WEIGHTS;
pub use linear_cm2::linear_cm2;
pub use norm::{group_norm, layer_norm, softmax};
pub use pool::{pool2d, resize_tf1, upload_image_bytes, Pool, PoolOp};
pub use winograd::winograd_scratch_bytes;

use crate::context::Context;
use crate::error::{ensure, Error, Result};
use crate::pipeline::Kernel;
use crate::recorder::Recorder;
use crate::tensor::{Dtype, Tensor};
use std::sync::Arc;

/// The pipeline of the variant of `kernel` whose parameters include `want`.
fn kernel(ctx: &Context, name: &'static str, dtype: Dtype, want: &[(&str, u32)], bindings: u32) -> Result<Arc<Kernel>> {
    let variant = vkdiff_kernels::find(name, dtype, want)
        .ok_or_else(|| Error::NoVariant { kernel: name, want: format!("{dtype:?} {want:?}") })?;
    ctx.kernel(variant, bindings)
}

/// The first of `variants` (kernel name and values per invocation step, widest first, the last
/// one value) whose width divides every count the kernel indexes by, and that width, by which
/// the caller divides those counts (kernels/wgsl/unit_1.wgsl, unit_2.wgsl, unit_4.wgsl).
fn unit_kernel(
    ctx: &Context,
    variants: &[(&'static str, usize)],
    dtype: Dtype,
    want: &[(&str, u32)],
    bindings: u32,
    counts: &[usize],
) -> Result<(Arc<Kernel>, usize)> {
    let fits = |&&(_, width): &&(&str, usize)| counts.iter().all(|c| c.is_multiple_of(width));
    let (name, width) = *variants.iter().find(fits).unwrap_or(&variants[variants.len() - 1]);
    Ok((kernel(ctx, name, dtype, want, bindings)?, width))
}

/// All tensors share one storage dtype, which the device supports.
fn same_dtype(ctx: &Context, op: &str, tensors: &[&Tensor]) -> Result<Dtype> {
    let dtype = tensors[0].dtype();
    ensure(tensors.iter().all(|t| t.dtype() == dtype), || format!("{op}: tensors mix f32 and f16"))?;
    ensure(dtype == Dtype::F32 || ctx.info().supports_f16(), || {
        format!("{op}: device `{}` has no f16 storage", ctx.info().name)
    })?;
    Ok(dtype)
}

/// Records `groups` workgroups of a kernel whose linear workgroup index is `y · groups_x + x`
/// (element-wise and row kernels): they are spread over x and y so neither passes the 65535
/// Vulkan guarantees, and `groups_x` is appended as the last push-constant word.
/// Workgroups for `n` elements, 64 per workgroup (kernels/wgsl/grid.wgsl).
fn element_groups(n: usize) -> usize {
    n.div_ceil(64)
}

fn dispatch_flat(
    rec: &mut Recorder,
    k: &Arc<Kernel>,
    reads: &[&Tensor],
    writes: &[&Tensor],
    push: &[u32],
    groups: usize,
) -> Result<()> {
    let gx = groups.clamp(1, 65535);
    let words: Vec<u32> = push.iter().copied().chain([gx as u32]).collect();
    rec.dispatch(k, reads, writes, &words, [gx as u32, groups.div_ceil(gx) as u32, 1])
}

/// Push-constant words of a u32 field list with floats stored as their bits.
fn f(x: f32) -> u32 {
    x.to_bits()
}

fn u(x: usize) -> u32 {
    x as u32
}

/// A tensor whose last dimension is `c` and leading dimensions multiply to the rest.
fn rows_of(t: &Tensor, what: &str) -> Result<(usize, usize)> {
    let c = *t.shape().last().ok_or_else(|| Error::Shape(format!("{what}: scalar tensor")))?;
    ensure(c > 0, || format!("{what}: empty last dimension"))?;
    Ok((t.numel() / c, c))
}
