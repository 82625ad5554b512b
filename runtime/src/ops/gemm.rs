//! Matrix products: batched GEMM with optional bias and accumulation, and `linear`.

use super::bands::{bands, elem, fit, row_view, rows_per_band, span_view};
use super::gemm_family::{dispatch_gemm_family, small, GemmKernels, GemmShape};
use super::{f, same_dtype, u};
use crate::arena::Arena;
use crate::error::{ensure, Result};
use crate::kernel_choice::plan::GemmFamily;
use crate::kernel_choice::tuned::KernelPick;
use crate::kernel_choice::tuning::{name_parts, pick, Tunable};
use crate::recorder::Recorder;
use crate::tensor::Tensor;

/// C[i] = alpha · A[i]·B[i] (+ bias) (+ C[i] if `accumulate`) for i < batch, row-major with the
/// given leading dimensions and batch strides (0 shares an operand across the batch). With
/// `b_transposed`, B is stored N×K (a PyTorch weight) and ldb is its row stride. With `geglu`
/// (B stored N×K, N a multiple of [`GEGLU_COLUMNS`], no accumulation), C has N/2 columns:
/// GEGLU of the product, value·GELU_erf(gate) of its columns j and N/2 + j, as diffusers'
/// `GEGLU` after its projection.
#[derive(Clone, Debug)]
pub struct Matmul {
    pub batch: usize,
    pub m: usize,
    pub n: usize,
    pub k: usize,
    pub lda: usize,
    pub ldb: usize,
    pub ldc: usize,
    pub a_batch: usize,
    pub b_batch: usize,
    pub c_batch: usize,
    pub b_transposed: bool,
    pub alpha: f32,
    pub accumulate: bool,
    pub geglu: bool,
}

/// What N of a product with GEGLU fused must be a multiple of: the value/gate blocks of every
/// kernel family (16 columns each in the tiled kernel) pair up whole.
pub const GEGLU_COLUMNS: usize = 32;

impl Matmul {
    /// A dense (M×K)·(K×N) product, or (M×K)·(N×K)ᵀ when `b_transposed`.
    pub fn dense(m: usize, n: usize, k: usize, b_transposed: bool) -> Matmul {
        Matmul {
            batch: 1,
            m,
            n,
            k,
            lda: k,
            ldb: if b_transposed { k } else { n },
            ldc: n,
            a_batch: m * k,
            b_batch: 0,
            c_batch: m * n,
            b_transposed,
            alpha: 1.0,
            accumulate: false,
            geglu: false,
        }
    }

    /// A PyTorch `Linear` (N×K weight) with GEGLU fused: C is M×N/2, dense.
    pub fn linear_geglu(m: usize, n: usize, k: usize) -> Matmul {
        Matmul { geglu: true, ldc: n / 2, c_batch: m * n / 2, ..Matmul::dense(m, n, k, true) }
    }

    /// Columns of C: N, or N/2 with GEGLU fused.
    fn c_cols(&self) -> usize {
        if self.geglu {
            self.n / 2
        } else {
            self.n
        }
    }

    fn fits_vec4(&self) -> bool {
        [self.n, self.k, self.lda, self.ldb, self.ldc, self.a_batch, self.b_batch, self.c_batch]
            .iter()
            .all(|x| x % 4 == 0)
    }

    /// Whether the matrix-unit kernels can read A and B in units of 8 (C is stored in fours).
    fn fits_vec8(&self) -> bool {
        let along_n = if self.b_transposed { 0 } else { self.n };
        self.fits_vec4() && [self.k, self.lda, self.ldb, self.a_batch, self.b_batch, along_n].iter().all(|x| x % 8 == 0)
    }

    /// Highest element index + 1 an operand is read or written at.
    fn extent(batch: usize, batch_stride: usize, rows: usize, ld: usize, cols: usize) -> usize {
        (batch - 1) * batch_stride + (rows - 1) * ld + cols
    }
}

/// Records C = alpha·A·B (+ bias) (+ C) as described by `spec`. A single product whose A or C
/// passes the binding limit runs in bands of rows, each a product of its own.
pub fn matmul(
    rec: &mut Recorder,
    a: &Tensor,
    b: &Tensor,
    bias: Option<&Tensor>,
    c: &Tensor,
    spec: &Matmul,
) -> Result<()> {
    if spec.batch > 1 && !fit(rec.context(), &[a, b, c]) {
        return matmul_per_batch(rec, a, b, bias, c, spec);
    }
    if fit(rec.context(), &[a, c]) || spec.batch != 1 || spec.lda == 0 || spec.ldc == 0 {
        return matmul_whole(rec, a, b, bias, c, spec);
    }
    let rows_of = |t: &Tensor, ld: usize| t.numel().is_multiple_of(ld).then(|| t.numel() / ld);
    ensure(rows_of(a, spec.lda) >= Some(spec.m) && rows_of(c, spec.ldc) >= Some(spec.m), || {
        format!(
            "matmul: A {:?} or C {:?} pass the binding limit and are not whole rows of {spec:?}",
            a.shape(),
            c.shape()
        )
    })?;
    let per = rows_per_band(rec.context(), "matmul", &[spec.lda * elem(a), spec.ldc * elem(c)], 0, 64)?;
    for rows in bands(spec.m, per) {
        let band =
            Matmul { m: rows.len(), a_batch: rows.len() * spec.lda, c_batch: rows.len() * spec.ldc, ..spec.clone() };
        matmul_whole(rec, &row_view(a, spec.lda, rows.clone())?, b, bias, &row_view(c, spec.ldc, rows)?, &band)?;
    }
    Ok(())
}

/// A batched product past the binding limit: one product per batch entry, each on views of
/// its own operands (shared ones whole), which must start on the binding alignment.
fn matmul_per_batch(
    rec: &mut Recorder,
    a: &Tensor,
    b: &Tensor,
    bias: Option<&Tensor>,
    c: &Tensor,
    spec: &Matmul,
) -> Result<()> {
    let (b_rows, b_cols) = if spec.b_transposed { (spec.n, spec.k) } else { (spec.k, spec.n) };
    for i in 0..spec.batch {
        let view = |t: &Tensor, stride: usize, rows: usize, ld: usize, cols: usize| -> Result<Tensor> {
            if stride == 0 {
                return Ok(t.clone());
            }
            let start = i * stride;
            let (v, before) = span_view(t, start..start + Matmul::extent(1, 0, rows, ld, cols))?;
            ensure(before == 0, || {
                format!("matmul: batch {i} of {:?} starts off the device's binding alignment", t.shape())
            })?;
            Ok(v)
        };
        let one = Matmul { batch: 1, ..spec.clone() };
        let (av, bv, cv) = (
            view(a, spec.a_batch, spec.m, spec.lda, spec.k)?,
            view(b, spec.b_batch, b_rows, spec.ldb, b_cols)?,
            view(c, spec.c_batch, spec.m, spec.ldc, spec.c_cols())?,
        );
        matmul(rec, &av, &bv, bias, &cv, &one)?;
    }
    Ok(())
}

fn matmul_whole(
    rec: &mut Recorder,
    a: &Tensor,
    b: &Tensor,
    bias: Option<&Tensor>,
    c: &Tensor,
    spec: &Matmul,
) -> Result<()> {
    let s = spec;
    ensure(s.batch > 0 && s.m > 0 && s.n > 0 && s.k > 0, || format!("matmul: empty shape {s:?}"))?;
    ensure(!s.geglu || (s.b_transposed && !s.accumulate && s.n.is_multiple_of(GEGLU_COLUMNS)), || {
        format!("matmul: GEGLU needs B stored N×K, N a multiple of {GEGLU_COLUMNS} and no accumulation: {s:?}")
    })?;
    let dtype = same_dtype(rec.context(), "matmul", &[a, b, c])?;
    let (b_rows, b_cols) = if s.b_transposed { (s.n, s.k) } else { (s.k, s.n) };
    ensure(a.numel() >= Matmul::extent(s.batch, s.a_batch, s.m, s.lda, s.k), || {
        format!("matmul: A {:?} too small for {s:?}", a.shape())
    })?;
    ensure(b.numel() >= Matmul::extent(s.batch, s.b_batch, b_rows, s.ldb, b_cols), || {
        format!("matmul: B {:?} too small for {s:?}", b.shape())
    })?;
    ensure(c.numel() >= Matmul::extent(s.batch, s.c_batch, s.m, s.ldc, s.c_cols()), || {
        format!("matmul: C {:?} too small for {s:?}", c.shape())
    })?;
    if let Some(bias) = bias {
        ensure(bias.numel() >= s.n && bias.dtype() == dtype, || {
            format!("matmul: bias {:?} for N = {}", bias.shape(), s.n)
        })?;
    }
    let common = push_constants(s, bias.is_some());
    let record = |rec: &mut Recorder, pick: KernelPick, reads: &[&Tensor], c: &Tensor| {
        // Without a bias the kernel never reads binding 2; C stands in for it.
        let operands = [reads[0], reads[1], reads.get(2).copied().unwrap_or(c)];
        if let Some(tile) = super::linear_cm2::chosen_tile(rec.context(), pick.probe, s, dtype) {
            return super::linear_cm2::record(rec, operands, c, s, &common, &tile);
        }
        let shape = GemmShape { m: s.m, n: s.n, k: s.k, batch: s.batch, vec4: s.fits_vec4(), vec8: s.fits_vec8() };
        let kernels = (GemmKernels::MATMUL, dtype, &[("BT", s.b_transposed as u32), ("GE", s.geglu as u32)][..]);
        dispatch_gemm_family(rec, kernels, pick.tile, &shape, &operands, c, &common)
    };
    let reads: Vec<&Tensor> = [a, b].into_iter().chain(bias).collect();
    let describe = || {
        let dense = s.lda == s.k && s.ldc == s.c_cols() && s.ldb == if s.b_transposed { s.k } else { s.n };
        let extras = name_parts(&[
            (bias.is_some(), " + bias"),
            (s.accumulate, " + C"),
            (s.geglu, ", GEGLU"),
            (!dense, ", strided"),
        ]);
        let op = match (s.batch, s.b_transposed) {
            (1, true) => format!("linear {}×{}×{}{extras} {dtype:?}", s.m, s.n, s.k),
            _ => format!("matmul {} × {}×{}×{}{extras} {dtype:?}", s.batch, s.m, s.n, s.k),
        };
        Tunable { key: format!("matmul {s:?} {dtype:?} bias {}", bias.is_some()), op, tiles: true }
    };
    let pick = pick(rec, (&reads, c), rec.context().choices().linear, describe, &record);
    record(rec, pick, &reads, c)
}

/// The push constants of the product `s`: gemm_common.wgsl's GemmParams, then
/// a_matrix_rows.wgsl's AParams.
pub(super) fn push_constants(s: &Matmul, bias: bool) -> [u32; 11] {
    let flags = bias as u32 | (s.accumulate as u32) << 1;
    [u(s.m), u(s.n), u(s.k), u(s.ldb), u(s.ldc), u(s.b_batch), u(s.c_batch), flags, f(s.alpha), u(s.lda), u(s.a_batch)]
}

/// A PyTorch `Linear` followed by GEGLU (diffusers' `GEGLU`: value first, gate second):
/// out[.., N/2] = value · GELU_erf(gate) of x[.., K] · wᵀ (+ bias), w stored [N, K]. Fused into
/// the product's epilogue, so the N-wide projection is never stored, where that measured faster:
/// the subgroup kernels (lavapipe: 1.07× in f32, 1.14× in f16) with N a multiple of
/// [`GEGLU_COLUMNS`] (every SDXL width), full compiles and products that are not [`small`] (the
/// fused variant is one more JIT: on Mesa 25 it made the README's demo about 10 s slower from a
/// cold cache). Elsewhere through a temporary from `scratch` and the GEGLU kernel: on an H200
/// the fused product ran 1.3× slower than product and kernel on the matrix units (the UNet 222
/// against 208 ms) and 1.04× slower on the tiled ones.
pub fn linear_geglu(
    rec: &mut Recorder,
    (x, w, bias): (&Tensor, &Tensor, Option<&Tensor>),
    out: &Tensor,
    scratch: &Arena,
) -> Result<()> {
    ensure(w.shape().len() == 2, || format!("linear_geglu: weight must be [out, in], got {:?}", w.shape()))?;
    let (n, k) = (w.shape()[0], w.shape()[1]);
    ensure(x.shape().last() == Some(&k), || format!("linear_geglu: input {:?} does not end in {k}", x.shape()))?;
    let m = x.numel() / k;
    ensure(n.is_multiple_of(2) && out.numel() * 2 == m * n, || {
        format!("linear_geglu: output {:?} is not {m}×{}", out.shape(), n / 2)
    })?;
    let ctx = rec.context();
    let fuse = ctx.choices().gemm_family == GemmFamily::Subgroup
        && n.is_multiple_of(GEGLU_COLUMNS)
        && !ctx.choices().quick_compile
        && !small(m, n, k);
    if !fuse {
        let projected = scratch.tensor(&[m, n], x.dtype())?;
        matmul(rec, x, w, bias, &projected, &Matmul::dense(m, n, k, true))?;
        return super::geglu(rec, &projected, out);
    }
    matmul(rec, x, w, bias, out, &Matmul::linear_geglu(m, n, k))
}

/// A PyTorch `Linear`: out[.., N] = x[.., K] · wᵀ (+ bias), w stored [N, K].
pub fn linear(rec: &mut Recorder, x: &Tensor, w: &Tensor, bias: Option<&Tensor>, out: &Tensor) -> Result<()> {
    ensure(w.shape().len() == 2, || format!("linear: weight must be [out, in], got {:?}", w.shape()))?;
    let (n, k) = (w.shape()[0], w.shape()[1]);
    ensure(x.shape().last() == Some(&k), || format!("linear: input {:?} does not end in {k}", x.shape()))?;
    let m = x.numel() / k;
    ensure(out.numel() == m * n, || format!("linear: output {:?} is not {m}×{n}", out.shape()))?;
    matmul(rec, x, w, bias, out, &Matmul::dense(m, n, k, true))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_matrix_units_read_units_of_eight_where_a_and_b_allow() {
        assert!(Matmul::dense(64, 64, 64, false).fits_vec8());
        assert!(Matmul::dense(64, 36, 64, true).fits_vec8(), "B N×K: N only needs the vec4 grid");
        assert!(!Matmul::dense(64, 36, 64, false).fits_vec8(), "B K×N is read along N");
        assert!(!Matmul::dense(64, 64, 36, true).fits_vec8(), "K");
        let strided = Matmul { lda: 68, a_batch: 64 * 68, ..Matmul::dense(64, 64, 64, true) };
        assert!(strided.fits_vec4() && !strided.fits_vec8(), "A's row stride");
        let c_in_fours = Matmul { ldc: 68, c_batch: 64 * 68, ..Matmul::dense(64, 64, 64, true) };
        assert!(c_in_fours.fits_vec8(), "C is stored in units of 4");
    }
}
