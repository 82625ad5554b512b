//! Deterministic data and comparisons against f64 references that name the worst element.

use vkdiff_runtime::{uniform_values, Dtype};

/// Deterministic values uniform in [-1, 1) (the runtime's [`uniform_values`]).
pub fn random(n: usize, seed: u64) -> Vec<f32> {
    uniform_values(n, seed)
}

/// The values a tensor of `dtype` actually holds after upload.
pub fn stored(x: &[f32], dtype: Dtype) -> Vec<f32> {
    match dtype {
        Dtype::F32 => x.to_vec(),
        Dtype::F16 => x.iter().map(|&v| half::f16::from_f32(v).to_f32()).collect(),
    }
}

/// Relative tolerance of one stored output value: f32 storage is exact to ~1e-7, f16 storage
/// rounds every output to 11 significant bits (relative error up to 2^-11 ≈ 4.9e-4).
pub fn storage_rtol(dtype: Dtype) -> f64 {
    match dtype {
        Dtype::F32 => 1e-6,
        Dtype::F16 => 1e-3,
    }
}

/// Fails unless |got[i] - want[i]| ≤ bound[i] for every i, naming the worst element.
pub fn assert_within(what: &str, got: &[f32], want: &[f64], bound: impl Fn(usize) -> f64) {
    assert_eq!(got.len(), want.len(), "{what}: length");
    let mut worst = (0usize, 0.0f64);
    for (i, (&g, &w)) in got.iter().zip(want).enumerate() {
        let diff = (g as f64 - w).abs();
        assert!(diff.is_finite(), "{what}: element {i} is {g}, want {w}");
        let excess = if diff == 0.0 { 0.0 } else { diff / bound(i) };
        if excess > worst.1 {
            worst = (i, excess);
        }
    }
    let i = worst.0;
    assert!(
        worst.1 <= 1.0 && worst.1.is_finite(),
        "{what}: element {i} is {}, want {} (error {:.3e} > bound {:.3e})",
        got[i],
        want[i],
        (got[i] as f64 - want[i]).abs(),
        bound(i)
    );
}

/// `assert_within` with |err| ≤ atol + rtol·|want|.
pub fn assert_close(what: &str, got: &[f32], want: &[f64], atol: f64, rtol: f64) {
    assert_within(what, got, want, |i| atol + rtol * want[i].abs());
}

pub const DTYPES: [Dtype; 2] = [Dtype::F32, Dtype::F16];
