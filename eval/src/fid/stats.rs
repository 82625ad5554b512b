//! FID and KID from feature rows (row-major `N × D` f32), as torch-fidelity's `metric_fid.py` and
//! `metric_kid.py` define them, computed in f64 (held to torch-fidelity by `tests/fid_stats.rs`).

use super::numpy_rng::RandomState;
use crate::{EvalError, Result};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::matmul::matmul;
use faer::linalg::matmul::triangular::{self, BlockStructure};
use faer::linalg::qr::no_pivoting::factor::{qr_in_place, qr_in_place_scratch, recommended_block_size};
use faer::{get_global_parallelism, Accum, Mat, MatRef};

/// Fréchet distance between Gaussians fitted to two feature sets: with `mu` the row means and
/// `sigma` the unbiased covariances (`np.cov(rowvar=False)`),
/// `|mu1 − mu2|² + tr σ1 + tr σ2 − 2 tr sqrt(σ1 σ2)`.
///
/// torch-fidelity takes `tr sqrt(σ1 σ2)` as the sum of the real parts of the complex square
/// roots of `eigvals(σ1 · σ2)`, a non-symmetric `D × D` eigenproblem whose many zero eigenvalues
/// (rank ≤ N − 1 < D) come out as noise of either sign. We use the same quantity in a better
/// conditioned form: write each covariance as `σ = FᵀF` (F = the centred rows over sqrt(N − 1),
/// or for N > D the `D × D` R of their QR decomposition, so `RᵀR = AᵀA = σ` without ever
/// squaring). The eigenvalues of `σ1σ2 = F1ᵀF1F2ᵀF2` are, besides zeros, those of
/// `(F1F2ᵀ)ᵀ(F1F2ᵀ)`, i.e. the squared singular values of `F1F2ᵀ`, so
/// `tr sqrt(σ1σ2)` = the sum of the singular values of `F1F2ᵀ` (at most `min(N, D)` square).
/// In exact arithmetic this is torch-fidelity's value (its real parts clamp the negative noise,
/// the singular values need no clamp), and it is cheaper and stabler: `N1 × N2` instead of
/// `D × D` for small sets, no `D × D` covariance formed, and no square root of round-off.
pub fn fid(a: &[f32], b: &[f32], dim: usize) -> Result<f64> {
    let (mu1, a) = centred(a, dim, "FID set 1")?;
    let (mu2, b) = centred(b, dim, "FID set 2")?;
    let mean_term: f64 = mu1.iter().zip(&mu2).map(|(x, y)| (x - y) * (x - y)).sum();
    let traces = a.squared_norm_l2() + b.squared_norm_l2();
    let (f1, f2) = cov_factors(a, b);
    let covmean = trace_sqrt_product(f1.as_ref(), f2.as_ref())?;
    Ok(mean_term + traces - 2.0 * covmean)
}

/// Row means (f64) and the centred rows over sqrt(N − 1), so that `AᵀA` is `np.cov`'s matrix.
fn centred(x: &[f32], dim: usize, name: &str) -> Result<(Vec<f64>, Mat<f64>)> {
    let n = rows(x, dim, name)?;
    let mut mu = vec![0f64; dim];
    for row in x.chunks_exact(dim) {
        mu.iter_mut().zip(row).for_each(|(m, &v)| *m += v as f64);
    }
    mu.iter_mut().for_each(|m| *m /= n as f64);
    let scale = 1.0 / ((n - 1) as f64).sqrt();
    let a = Mat::from_fn(n, dim, |i, j| (x[i * dim + j] as f64 - mu[j]) * scale);
    Ok((mu, a))
}

/// Factors with `FᵀF = AᵀA` for both sets: the centred rows themselves, or for a set of more
/// than D rows the `D × D` R of their QR decomposition, unless the other set has few enough rows
/// `k` that the SVD of the `k × N` product (which starts with a QR of that `N × k` matrix) is the
/// cheaper way.
fn cov_factors(a: Mat<f64>, b: Mat<f64>) -> (Mat<f64>, Mat<f64>) {
    let d = a.ncols();
    let factor = |x: Mat<f64>, k: usize| if x.nrows() <= d || k * (d + k) <= d * d { x } else { r_factor(x) };
    let (n1, n2) = (a.nrows(), b.nrows());
    (factor(a, n2), factor(b, n1))
}

/// The upper-trapezoidal R of `A = QR` (`min(N, D) × D`); `RᵀR = AᵀA` since Q is orthogonal.
fn r_factor(mut a: Mat<f64>) -> Mat<f64> {
    let (n, d) = a.shape();
    let k = n.min(d);
    let block = recommended_block_size::<f64>(n, d);
    let par = get_global_parallelism();
    let mut coeff = Mat::<f64>::zeros(block, k);
    let scratch = qr_in_place_scratch::<f64>(n, d, block, par, Default::default());
    let mut mem = MemBuffer::new(scratch);
    qr_in_place(a.as_mut(), coeff.as_mut(), par, MemStack::new(&mut mem), Default::default());
    // The strictly lower part now holds the Householder vectors, not R.
    Mat::from_fn(k, d, |i, j| if i <= j { a[(i, j)] } else { 0.0 })
}

/// `tr sqrt(F1ᵀF1 · F2ᵀF2)` as the sum of the singular values of `F1 F2ᵀ` (see [`fid`]).
fn trace_sqrt_product(f1: MatRef<f64>, f2: MatRef<f64>) -> Result<f64> {
    let mut c = Mat::<f64>::zeros(f1.nrows(), f2.nrows());
    matmul(c.as_mut(), Accum::Replace, f1, f2.transpose(), 1.0, get_global_parallelism());
    let s = c.singular_values().map_err(|e| {
        EvalError::NotFinite(format!("FID: the SVD of the cross-covariance factor did not converge ({e:?})"))
    })?;
    Ok(s.iter().sum())
}

/// torch-fidelity's KID settings (`kid_subsets`, `kid_subset_size`, `kid_kernel_poly_*`,
/// `rng_seed`); `Default` is its defaults.
#[derive(Clone, Debug)]
pub struct KidOptions {
    pub subsets: usize,
    pub subset_size: usize,
    pub degree: u32,
    /// `None`: 1 / D.
    pub gamma: Option<f64>,
    pub coef0: f64,
    pub seed: u32,
}

impl Default for KidOptions {
    fn default() -> Self {
        KidOptions { subsets: 100, subset_size: 1000, degree: 3, gamma: None, coef0: 1.0, seed: 2020 }
    }
}

/// Mean and population standard deviation (`np.std`) of the subsets' MMD² estimates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Kid {
    pub mean: f64,
    pub std: f64,
    /// The subset size used: `opts.subset_size`, clamped to the smaller set.
    pub subset_size: usize,
}

/// Kernel Inception distance: the unbiased MMD² with the polynomial kernel
/// `(gamma · x·y + coef0)^degree`, over `subsets` pairs of random subsets drawn as torch-fidelity
/// draws them (`RandomState(seed)`, `choice(n1, m, replace=False)` then `choice(n2, ...)` per
/// subset). torch-fidelity refuses sets smaller than `subset_size`; we clamp `m` to the smaller
/// set instead and report it in [`Kid::subset_size`]. f64 throughout, where torch-fidelity uses
/// float32: its MMD² is a small difference of large kernel sums, so ours is the more exact.
pub fn kid(a: &[f32], b: &[f32], dim: usize, opts: &KidOptions) -> Result<Kid> {
    let n1 = rows(a, dim, "KID set 1")?;
    let n2 = rows(b, dim, "KID set 2")?;
    let m = opts.subset_size.min(n1).min(n2);
    if opts.subsets == 0 || m < 2 {
        return Err(EvalError::Invalid(format!(
            "KID: needs at least 1 subset of at least 2 rows (got {} subsets of {})",
            opts.subsets, opts.subset_size
        )));
    }
    let kernel = Poly { gamma: opts.gamma.unwrap_or(1.0 / dim as f64), coef0: opts.coef0, degree: opts.degree };
    let mut rng = RandomState::new(opts.seed);
    let draws: Vec<(Vec<usize>, Vec<usize>)> = (0..opts.subsets)
        .map(|_| {
            let i1 = rng.choice_without_replacement(n1, m);
            (i1, rng.choice_without_replacement(n2, m))
        })
        .collect();
    let whole = whole_sets_cheaper(n1, n2, m, opts.subsets);
    let mmds = subset_mmds(a, b, dim, &draws, &kernel, whole);
    let mean = mmds.iter().sum::<f64>() / mmds.len() as f64;
    let var = mmds.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / mmds.len() as f64;
    Ok(Kid { mean, std: var.sqrt(), subset_size: m })
}

/// MMD² of each drawn pair of subsets (rows of the row-major `x`, `y`), from kernel matrices over
/// the whole sets or per subset.
fn subset_mmds(
    x: &[f32],
    y: &[f32],
    dim: usize,
    draws: &[(Vec<usize>, Vec<usize>)],
    k: &Poly,
    whole: bool,
) -> Vec<f64> {
    if whole {
        let (xs, ys) = (gather(x, dim, 0..x.len() / dim), gather(y, dim, 0..y.len() / dim));
        let kernels = Kernels::new(row_major(&xs, dim), row_major(&ys, dim), k);
        return draws.iter().map(|(i1, i2)| kernels.mmd2(i1, i2)).collect();
    }
    draws
        .iter()
        .map(|(i1, i2)| {
            let (xs, ys) = (gather(x, dim, i1.iter().copied()), gather(y, dim, i2.iter().copied()));
            let all: Vec<usize> = (0..i1.len()).collect();
            Kernels::new(row_major(&xs, dim), row_major(&ys, dim), k).mmd2(&all, &all)
        })
        .collect()
}

/// The rows `idx` of row-major `f` in f64, row-major: whole rows are contiguous, so gathering a
/// subset of a large set stays cache-friendly.
fn gather(f: &[f32], dim: usize, idx: impl Iterator<Item = usize>) -> Vec<f64> {
    idx.flat_map(|i| f[i * dim..(i + 1) * dim].iter().map(|&v| v as f64)).collect()
}

fn row_major(f: &[f64], dim: usize) -> MatRef<'_, f64> {
    MatRef::from_row_major_slice(f, f.len() / dim, dim)
}

/// Kernel matrices over whole sets (subsets then just index them) cost `(n1² + n2² + n1·n2)·D`
/// once instead of `3·m²·D` per subset; worth it when that is less work and fits in memory.
fn whole_sets_cheaper(n1: usize, n2: usize, m: usize, subsets: usize) -> bool {
    const MAX_ENTRIES: usize = 1 << 26; // 512 MiB of f64 for the three kernel matrices
    let entries = n1 * n1 + n2 * n2 + n1 * n2;
    entries <= MAX_ENTRIES && entries <= 3 * m * m * subsets
}

struct Poly {
    gamma: f64,
    coef0: f64,
    degree: u32,
}

impl Poly {
    /// `(gamma · P Qᵀ + coef0)^degree`; for `P = Q` only the lower half is multiplied, then mirrored.
    fn matrix(&self, p: MatRef<f64>, q: MatRef<f64>, same: bool) -> Mat<f64> {
        let (par, full) = (get_global_parallelism(), BlockStructure::Rectangular);
        let mut g = Mat::<f64>::zeros(p.nrows(), q.nrows());
        let dst = if same { BlockStructure::TriangularLower } else { full };
        triangular::matmul(g.as_mut(), dst, Accum::Replace, p, full, q.transpose(), full, 1.0, par);
        if same {
            (0..g.ncols()).for_each(|j| (0..j).for_each(|i| g[(i, j)] = g[(j, i)]));
        }
        for j in 0..g.ncols() {
            let col = g.col_as_slice_mut(j);
            col.iter_mut().for_each(|v| *v = (self.gamma * *v + self.coef0).powi(self.degree as i32));
        }
        g
    }
}

/// `k(X, X)`, `k(Y, Y)`, `k(X, Y)` over some rows of the two sets.
struct Kernels {
    xx: Mat<f64>,
    yy: Mat<f64>,
    xy: Mat<f64>,
}

impl Kernels {
    fn new(x: MatRef<f64>, y: MatRef<f64>, k: &Poly) -> Self {
        Kernels { xx: k.matrix(x, x, true), yy: k.matrix(y, y, true), xy: k.matrix(x, y, false) }
    }

    /// torch-fidelity's `mmd2(..., mmd_est="unbiased")` on the rows `ix` of X and `iy` of Y
    /// (distinct indices, so the subset's diagonal is the kernel's).
    fn mmd2(&self, ix: &[usize], iy: &[usize]) -> f64 {
        let m = ix.len() as f64;
        let off_diagonal =
            |k: &Mat<f64>, idx: &[usize]| block_sum(k, idx, idx) - idx.iter().map(|&i| k[(i, i)]).sum::<f64>();
        let same = off_diagonal(&self.xx, ix) + off_diagonal(&self.yy, iy);
        same / (m * (m - 1.0)) - 2.0 * block_sum(&self.xy, ix, iy) / (m * m)
    }
}

/// Sum of `k[rows, cols]`, a column at a time (columns are contiguous).
fn block_sum(k: &Mat<f64>, rows: &[usize], cols: &[usize]) -> f64 {
    cols.iter()
        .map(|&j| {
            let col = k.col_as_slice(j);
            rows.iter().map(|&i| col[i]).sum::<f64>()
        })
        .sum()
}

/// Number of rows of a feature set, after checking its shape and values.
fn rows(x: &[f32], dim: usize, name: &str) -> Result<usize> {
    if dim == 0 || !x.len().is_multiple_of(dim) {
        return Err(EvalError::Invalid(format!("{name}: {} values are not rows of dimension {dim}", x.len())));
    }
    let n = x.len() / dim;
    if n < 2 {
        return Err(EvalError::Invalid(format!("{name}: {n} feature row(s); at least 2 are needed")));
    }
    if let Some(i) = x.iter().position(|v| !v.is_finite()) {
        return Err(EvalError::Invalid(format!("{name}: row {} has a non-finite feature ({})", i / dim, x[i])));
    }
    Ok(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `n × d` features in [-1, 1) plus `shift`, deterministic per seed.
    fn features(seed: u32, n: usize, d: usize, shift: f32) -> Vec<f32> {
        let mut rng = RandomState::new(seed);
        (0..n * d).map(|_| (rng.next_u32() as f32 / 2f32.powi(31) - 1.0) + shift).collect()
    }

    fn rel(a: f64, b: f64) -> f64 {
        (a - b).abs() / b.abs().max(1e-300)
    }

    /// The centred rows and their R factor give the same `tr sqrt(σ1σ2)`, whatever the shapes.
    #[test]
    fn gram_and_r_factor_agree() {
        for (n1, n2, d) in [(10, 14, 32), (40, 9, 16), (25, 30, 25)] {
            let (_, a) = centred(&features(5, n1, d, 0.0), d, "a").unwrap();
            let (_, b) = centred(&features(6, n2, d, 0.3), d, "b").unwrap();
            let gram = trace_sqrt_product(a.as_ref(), b.as_ref()).unwrap();
            let r = trace_sqrt_product(r_factor(a.clone()).as_ref(), r_factor(b.clone()).as_ref()).unwrap();
            let mixed = trace_sqrt_product(r_factor(a).as_ref(), b.as_ref()).unwrap();
            assert!(rel(r, gram) < 1e-12 && rel(mixed, gram) < 1e-12, "{gram} {r} {mixed}");
        }
    }

    #[test]
    fn kid_whole_set_and_per_subset_kernels_agree() {
        let (n1, n2, d, m) = (30, 25, 16, 12);
        let (x, y) = (features(7, n1, d, 0.0), features(8, n2, d, 0.1));
        let mut rng = RandomState::new(9);
        let draws: Vec<_> =
            (0..5).map(|_| (rng.choice_without_replacement(n1, m), rng.choice_without_replacement(n2, m))).collect();
        let k = Poly { gamma: 1.0 / d as f64, coef0: 1.0, degree: 3 };
        let whole = subset_mmds(&x, &y, d, &draws, &k, true);
        let each = subset_mmds(&x, &y, d, &draws, &k, false);
        for (a, b) in whole.iter().zip(&each) {
            assert!((a - b).abs() < 1e-12 * b.abs().max(1e-3), "{a} {b}");
        }
    }
}
