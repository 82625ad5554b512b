//! Fused multi-head attention (flash-style: no Nq×Nk scores in memory).

use super::attention_products::{attention_by_products, rows_per_chunk};
use super::bands::{bands, elem, fit, span_view};
use super::copy_heads::{copy_heads, HeadSpan};
use super::{f, same_dtype, u};
use crate::context::Context;
use crate::error::{ensure, Error, Result};
use crate::kernel_choice::plan::GemmFamily;
use crate::kernel_choice::tuned::KernelPick;
use crate::kernel_choice::tuning::{pick, Tunable};
use crate::recorder::Recorder;
use crate::tensor::Dtype;
use crate::tensor::Tensor;

/// Where attention's operands live. Element (b, token, head, d) of each is at
/// `offset + b·batch + token·ld + head·head_dim + d`, so Q, K and V can be column slices of one
/// fused projection (row stride 3·heads·head_dim, offsets 0, C and 2C).
#[derive(Clone, Debug)]
pub struct AttentionLayout {
    pub batch: usize,
    pub heads: usize,
    pub head_dim: usize,
    pub q_tokens: usize,
    pub kv_tokens: usize,
    pub q_ld: usize,
    pub k_ld: usize,
    pub v_ld: usize,
    pub o_ld: usize,
    pub q_batch: usize,
    pub k_batch: usize,
    pub v_batch: usize,
    pub o_batch: usize,
    pub q_offset: usize,
    pub k_offset: usize,
    pub v_offset: usize,
    /// Query i attends to keys 0..=i only (CLIP's text transformer).
    pub causal: bool,
}

impl AttentionLayout {
    /// Dense [B, tokens, heads·head_dim] tensors for Q, K, V and the output.
    pub fn dense(batch: usize, heads: usize, head_dim: usize, q_tokens: usize, kv_tokens: usize) -> AttentionLayout {
        let w = heads * head_dim;
        AttentionLayout {
            batch,
            heads,
            head_dim,
            q_tokens,
            kv_tokens,
            q_ld: w,
            k_ld: w,
            v_ld: w,
            o_ld: w,
            q_batch: q_tokens * w,
            k_batch: kv_tokens * w,
            v_batch: kv_tokens * w,
            o_batch: q_tokens * w,
            q_offset: 0,
            k_offset: 0,
            v_offset: 0,
            causal: false,
        }
    }
}

/// Subgroup widths attention has variants for.
const WIDTHS: [u32; 3] = [4, 8, 16];

/// out = softmax(scale · Q·Kᵀ)·V for every batch and head; f16 heads of up to 64 values through
/// `VK_NV_cooperative_matrix2`'s probe where the context asks for it ([`crate::ProbeChoice`])
/// and the device runs it.
pub fn attention(
    rec: &mut Recorder,
    q: &Tensor,
    k: &Tensor,
    v: &Tensor,
    out: &Tensor,
    l: &AttentionLayout,
    scale: f32,
) -> Result<()> {
    let dtype = checked_dtype(rec, "attention", [q, k, v, out], l)?;
    if let Some(rows) = rows_per_chunk(rec, dtype, l) {
        return attention_by_products(rec, [q, k, v], out, l, scale, rows);
    }
    if !fit(rec.context(), &[q, k, v, out]) {
        return attention_banded(rec, [q, k, v], out, l, scale);
    }
    if !vec4_aligned(l) {
        return padded_attention(rec, [q, k, v], out, l, scale);
    }
    let record = |rec: &mut Recorder, pick: KernelPick, reads: &[&Tensor], out: &Tensor| {
        attention_checked(rec, pick.probe, [reads[0], reads[1], reads[2]], out, l, scale)
    };
    let describe = || Tunable {
        key: format!("attention {l:?} {dtype:?} {scale}"),
        op: format!("attention {}×{} tokens, {} heads × {} {dtype:?}", l.q_tokens, l.kv_tokens, l.heads, l.head_dim),
        tiles: false,
    };
    let pick = pick(rec, (&[q, k, v], out), rec.context().choices().attention, describe, &record);
    record(rec, pick, &[q, k, v], out)
}

/// [`attention`] once its layout, the binding limit and the vec4 grid are checked: on `probe`'s
/// tile where it asks for one that holds the (f16) heads, else the device's family.
fn attention_checked(
    rec: &mut Recorder,
    probe: crate::ProbeChoice,
    [q, k, v]: [&Tensor; 3],
    out: &Tensor,
    l: &AttentionLayout,
    scale: f32,
) -> Result<()> {
    let dtype = out.dtype();
    if let Some(tile) = super::attention_cm2::chosen_tile(rec.context(), probe, dtype, l.head_dim) {
        return super::attention_cm2::record(rec, [q, k, v], out, l, scale, &tile);
    }
    let ctx = rec.context().clone();
    let slots = u(l.head_dim / 4);
    // With quick compiles, narrow attention (tiny models) takes attention_wg, which Mesa 25's
    // JIT compiles in about a second, against 12–16 s for the subgroup variants and 34–94 s for
    // attention_rows (measured).
    let quick = ctx.choices().quick_compile && l.heads * l.head_dim < SMALL_CHANNELS;
    let found = cooperative_variant(&ctx, dtype, l.head_dim)
        .or_else(|| subgroup_variant(&ctx, dtype, slots).filter(|_| !quick))
        .or_else(|| tiled_variant(&ctx, dtype, l.head_dim).filter(|_| !quick))
        .or_else(|| rows_variant(dtype, slots).filter(|_| !quick));
    let variant = match found {
        Some(v) => v,
        None => vkdiff_kernels::variants("attention_wg", dtype)
            .filter(|v| v.param("DV").unwrap() * v.param("W").unwrap() >= slots)
            .min_by_key(|v| v.param("DV"))
            .ok_or_else(|| Error::Shape(format!("attention: head size {} is past the widest variant", l.head_dim)))?,
    };
    // Query rows per workgroup: TM, 4·FM on the matrix units, or attention_rows' one per invocation.
    let tm = variant.param("TM").or(variant.param("FM").map(|fm| 4 * fm)).unwrap_or(ROWS_PER_WORKGROUP) as usize;
    let kern = ctx.kernel(variant, 4)?;
    let push = push_constants(l, scale);
    rec.count_flops(4.0 * (l.batch * l.heads * l.q_tokens) as f64 * (l.kv_tokens * l.head_dim) as f64);
    rec.dispatch(&kern, &[q, k, v], &[out], &push, [u(l.q_tokens.div_ceil(tm)), u(l.heads), u(l.batch)])
}

/// The operands' dtype, once their layout `l` is checked against their sizes (`op` names the
/// caller in errors).
pub(super) fn checked_dtype(
    rec: &Recorder,
    op: &str,
    [q, k, v, out]: [&Tensor; 4],
    l: &AttentionLayout,
) -> Result<Dtype> {
    let dtype = same_dtype(rec.context(), op, &[q, k, v, out])?;
    ensure(l.batch > 0 && l.heads > 0 && l.q_tokens > 0 && l.kv_tokens > 0, || format!("{op}: empty layout {l:?}"))?;
    ensure(!l.causal || l.q_tokens == l.kv_tokens, || {
        format!("{op}: a causal mask needs as many queries as keys, got {l:?}")
    })?;
    let need = |ld: usize, bs: usize, tokens: usize| (l.batch - 1) * bs + (tokens - 1) * ld + l.heads * l.head_dim;
    let need_at = |off: usize, ld: usize, bs: usize, tokens: usize| off + need(ld, bs, tokens);
    ensure(q.numel() >= need_at(l.q_offset, l.q_ld, l.q_batch, l.q_tokens), || {
        format!("{op}: Q {:?} too small", q.shape())
    })?;
    ensure(k.numel() >= need_at(l.k_offset, l.k_ld, l.k_batch, l.kv_tokens), || {
        format!("{op}: K {:?} too small", k.shape())
    })?;
    ensure(v.numel() >= need_at(l.v_offset, l.v_ld, l.v_batch, l.kv_tokens), || {
        format!("{op}: V {:?} too small", v.shape())
    })?;
    ensure(out.numel() >= need(l.o_ld, l.o_batch, l.q_tokens), || format!("{op}: output {:?} too small", out.shape()))?;
    Ok(dtype)
}

/// Whether the head size and every stride and offset of `l` are multiples of 4, as the kernels
/// read the operands (vec4s).
pub(super) fn vec4_aligned(l: &AttentionLayout) -> bool {
    let strides = [
        l.head_dim, l.q_ld, l.k_ld, l.v_ld, l.o_ld, l.q_batch, l.k_batch, l.v_batch, l.o_batch, l.q_offset, l.k_offset,
        l.v_offset,
    ];
    strides.iter().all(|s| s % 4 == 0)
}

/// The kernels' parameters (attention_common.wgsl's `Params`).
pub(super) fn push_constants(l: &AttentionLayout, scale: f32) -> [u32; 16] {
    [
        u(l.q_tokens),
        u(l.kv_tokens),
        u(l.head_dim),
        u(l.q_ld),
        u(l.k_ld),
        u(l.v_ld),
        u(l.o_ld),
        u(l.q_batch),
        u(l.k_batch),
        u(l.v_batch),
        u(l.o_batch),
        f(scale),
        u(l.q_offset),
        u(l.k_offset),
        u(l.v_offset),
        l.causal as u32,
    ]
}

/// Attention with fewer channels (heads × head size) than this is small enough to take the
/// quickly compiled kernel: every SDXL, CLIP and VAE attention has 320 or more.
const SMALL_CHANNELS: usize = 256;

/// attention_rows' workgroup: 64 invocations, one query row each.
const ROWS_PER_WORKGROUP: u32 = 64;

/// The matrix-unit attention for f16 heads of up to 64 values, where the context runs its GEMMs
/// on the matrix units (the same fragment shape and subgroup width) and the device's workgroup
/// memory holds the variant's.
fn cooperative_variant(ctx: &Context, dtype: Dtype, head_dim: usize) -> Option<&'static vkdiff_kernels::Variant> {
    let fragment = ctx.info().cooperative_variant()?;
    if ctx.choices().gemm_family != GemmFamily::Cooperative || dtype != Dtype::F16 || head_dim > 64 {
        return None;
    }
    let want: Vec<(&str, u32)> = fragment.params().into_iter().chain([("DH", 64)]).collect();
    vkdiff_kernels::find("attention_coop", dtype, &want).filter(|v| {
        cooperative_workgroup_bytes(fragment.m, fragment.n, v.param("KF").unwrap()) <= ctx.info().max_shared_memory
    })
}

/// Workgroup memory of attention_coop.wgsl at fragments of `fm` rows and `fn_` columns with `kf`
/// key fragments per chunk (heads of 64): K and V rows (f16), the subgroups' scratch rows
/// (f32), probabilities (f16), each row's reference, sum and scale, and the subgroups' flags.
fn cooperative_workgroup_bytes(fm: u32, fn_: u32, kf: u32) -> u32 {
    let (keys, rows) = (kf * fn_, 4 * fm);
    2 * keys * (64 + 8) * 2 + rows * (keys.max(64) + 4) * 4 + rows * (keys + 8) * 2 + 3 * rows * 4 + 4 * 4
}

/// The register-blocked GPU attention, for heads of up to 64 values where the device has its
/// 32 KiB of workgroup memory (two tiles of 64×64 f32).
fn tiled_variant(ctx: &Context, dtype: Dtype, head_dim: usize) -> Option<&'static vkdiff_kernels::Variant> {
    let fits = head_dim <= 64 && ctx.info().holds_tiled_attention();
    vkdiff_kernels::find("attention_tiled", dtype, &[]).filter(|_| fits)
}

impl crate::DeviceInfo {
    /// Whether the device's workgroup memory holds attention_tiled.wgsl's two 64×64 f32 tiles.
    pub fn holds_tiled_attention(&self) -> bool {
        2 * 64 * 64 * 4 <= self.max_shared_memory
    }
}

/// The GPU attention variant with the fewest slots that hold a head of `slots` vec4s.
fn rows_variant(dtype: Dtype, slots: u32) -> Option<&'static vkdiff_kernels::Variant> {
    vkdiff_kernels::variants("attention_rows", dtype)
        .filter(|v| v.param("DS").unwrap() >= slots)
        .min_by_key(|v| v.param("DS"))
}

/// The subgroup attention variant for a head of `slots` vec4s at a width this device can pin,
/// its native width first, with the fewest slots per lane; none where the device takes no
/// subgroup attention ([`crate::DeviceInfo::subgroup_attention`]) or no width fits. Its operands
/// are read as 64-bit words where the context says so, as the GEMM's are.
fn subgroup_variant(ctx: &Context, dtype: Dtype, slots: u32) -> Option<&'static vkdiff_kernels::Variant> {
    if !ctx.info().subgroup_attention(ctx.choices().gpu_paths) {
        return None;
    }
    let native = ctx.info().subgroup_size;
    let mut widths: Vec<u32> = WIDTHS.iter().copied().filter(|&w| ctx.subgroup_ok(w)).collect();
    widths.sort_by_key(|&w| (w != native, w));
    let words = Some(u32::from(ctx.choices().word_loads));
    widths.iter().find_map(|&sg| {
        vkdiff_kernels::variants("attention", dtype)
            .filter(|v| v.param("SG") == Some(sg) && v.param("WD") == words && v.param("DV").unwrap() * sg >= slots)
            .min_by_key(|v| v.param("DV"))
    })
}

/// Attention on operands past the binding limit: one batch at a time on views of its rows
/// where those fit, else in groups of heads copied into dense operands that do.
fn attention_banded(
    rec: &mut Recorder,
    [q, k, v]: [&Tensor; 3],
    out: &Tensor,
    l: &AttentionLayout,
    scale: f32,
) -> Result<()> {
    let ctx = rec.context().clone();
    let span = |offset: usize, batch: usize, ld: usize, tokens: usize, b: usize| {
        let start = offset + b * batch;
        start..start + (tokens - 1) * ld + l.heads * l.head_dim
    };
    for b in 0..l.batch {
        let (qv, q_offset) = span_view(q, span(l.q_offset, l.q_batch, l.q_ld, l.q_tokens, b))?;
        let (kv, k_offset) = span_view(k, span(l.k_offset, l.k_batch, l.k_ld, l.kv_tokens, b))?;
        let (vv, v_offset) = span_view(v, span(l.v_offset, l.v_batch, l.v_ld, l.kv_tokens, b))?;
        // The kernel writes the output at offset 0 of its binding.
        let (ov, o_offset) = span_view(out, span(0, l.o_batch, l.o_ld, l.q_tokens, b))?;
        if o_offset == 0 && fit(&ctx, &[&qv, &kv, &vv, &ov]) {
            let one = AttentionLayout { batch: 1, q_offset, k_offset, v_offset, ..l.clone() };
            attention(rec, &qv, &kv, &vv, &ov, &one, scale)?;
        } else {
            attention_by_heads(rec, [q, k, v], out, l, b, scale)?;
        }
    }
    Ok(())
}

/// Batch `b` of attention in groups of heads, each copied into dense operands that fit one
/// binding (heads padded to a multiple of 4), attended, and copied back.
fn attention_by_heads(
    rec: &mut Recorder,
    [q, k, v]: [&Tensor; 3],
    out: &Tensor,
    l: &AttentionLayout,
    b: usize,
    scale: f32,
) -> Result<()> {
    let ctx = rec.context().clone();
    let padded = l.head_dim.next_multiple_of(4);
    let head_bytes = l.q_tokens.max(l.kv_tokens) * padded * elem(q);
    let per = (ctx.choices().binding_limit as usize / head_bytes).min(l.heads);
    ensure(per > 0, || {
        format!(
            "attention: one head of {head_bytes} bytes does not fit the {} byte binding limit",
            ctx.choices().binding_limit
        )
    })?;
    for heads in bands(l.heads, per) {
        let n = heads.len();
        let dense =
            AttentionLayout { causal: l.causal, ..AttentionLayout::dense(1, n, padded, l.q_tokens, l.kv_tokens) };
        let dense_span = HeadSpan { offset: 0, ld: n * padded, batch: 0, head_dim: padded };
        let strided = |offset: usize, batch: usize, ld: usize| HeadSpan {
            offset: offset + b * batch + heads.start * l.head_dim,
            ld,
            batch: 0,
            head_dim: l.head_dim,
        };
        let gather = |rec: &mut Recorder, t: &Tensor, from: HeadSpan, tokens: usize| -> Result<Tensor> {
            let to = ctx.zeros(&[tokens, n * padded], t.dtype())?;
            copy_heads(rec, t, &to, from, dense_span, 1, tokens, n)?;
            Ok(to)
        };
        let qd = gather(rec, q, strided(l.q_offset, l.q_batch, l.q_ld), l.q_tokens)?;
        let kd = gather(rec, k, strided(l.k_offset, l.k_batch, l.k_ld), l.kv_tokens)?;
        let vd = gather(rec, v, strided(l.v_offset, l.v_batch, l.v_ld), l.kv_tokens)?;
        let od = ctx.zeros(&[l.q_tokens, n * padded], out.dtype())?;
        attention(rec, &qd, &kd, &vd, &od, &dense, scale)?;
        copy_heads(rec, &od, out, dense_span, strided(0, l.o_batch, l.o_ld), 1, l.q_tokens, n)?;
    }
    Ok(())
}

/// Attention on operands whose head size or strides are not multiples of 4 (the kernel reads
/// vec4s): each copied into a dense layout with its heads padded by zeros to a multiple of 4,
/// which add nothing to Q·Kᵀ and only make output columns that are then left behind.
fn padded_attention(
    rec: &mut Recorder,
    [q, k, v]: [&Tensor; 3],
    out: &Tensor,
    l: &AttentionLayout,
    scale: f32,
) -> Result<()> {
    let ctx = rec.context().clone();
    let padded = l.head_dim.next_multiple_of(4);
    let dense = AttentionLayout {
        causal: l.causal,
        ..AttentionLayout::dense(l.batch, l.heads, padded, l.q_tokens, l.kv_tokens)
    };
    let span = |offset, ld, batch, head_dim| HeadSpan { offset, ld, batch, head_dim };
    let dense_span = |tokens: usize| span(0, l.heads * padded, tokens * l.heads * padded, padded);
    let pad = |rec: &mut Recorder, t: &Tensor, from: HeadSpan, tokens: usize| -> Result<Tensor> {
        let to = ctx.zeros(&[l.batch, tokens, l.heads * padded], t.dtype())?;
        copy_heads(rec, t, &to, from, dense_span(tokens), l.batch, tokens, l.heads)?;
        Ok(to)
    };
    let q_dense = pad(rec, q, span(l.q_offset, l.q_ld, l.q_batch, l.head_dim), l.q_tokens)?;
    let k_dense = pad(rec, k, span(l.k_offset, l.k_ld, l.k_batch, l.head_dim), l.kv_tokens)?;
    let v_dense = pad(rec, v, span(l.v_offset, l.v_ld, l.v_batch, l.head_dim), l.kv_tokens)?;
    let o_dense = ctx.zeros(&[l.batch, l.q_tokens, l.heads * padded], out.dtype())?;
    attention(rec, &q_dense, &k_dense, &v_dense, &o_dense, &dense, scale)?;
    copy_heads(
        rec,
        &o_dense,
        out,
        dense_span(l.q_tokens),
        span(0, l.o_ld, l.o_batch, l.head_dim),
        l.batch,
        l.q_tokens,
        l.heads,
    )
}

#[cfg(test)]
mod tests {
    use crate::device::tests::device;
    use crate::device::DeviceKind;

    #[test]
    fn tiled_attention_needs_32_kib_of_workgroup_memory() {
        let mut gpu = device(0, DeviceKind::Discrete, true);
        gpu.max_shared_memory = 32768;
        assert!(gpu.holds_tiled_attention());
        gpu.max_shared_memory = 16384;
        assert!(!gpu.holds_tiled_attention());
    }
}
