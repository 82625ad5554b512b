//! Before a context first runs products on the device's matrix units, one product is timed
//! there and on the shared-memory tiled kernels, and the two results are compared. Drivers
//! list cooperative-matrix shapes their hardware does not have (Mesa lowers Intel's 8×8×16 to
//! ordinary arithmetic on GPUs without XMX, lavapipe emulates them all), and a driver's
//! matrix-unit path can be wrong where its tiled one is right; neither shows in what the
//! device reports. So the units are kept only where they agree with the tiled kernels and are
//! not clearly slower.

use crate::kernel_choice::plan::MARGIN;

/// The trial product: SDXL's 640-channel attention projections for one 512² image (1024 tokens), in f16.
pub(crate) const M: usize = 1024;
pub(crate) const N: usize = 640;
pub(crate) const K: usize = 640;
/// The largest difference between the two families' results, relative to the largest result,
/// that still counts as agreement: both sum in f32 and round to f16 (2⁻¹¹ relative), in
/// different orders; a driver that garbles fragments misses by the results' own size.
pub const AGREEMENT: f32 = 1e-2;

/// What the trial found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MatrixUnitTrial {
    /// Time of one trial product on the matrix units and on the tiled kernels: device time from
    /// timestamps, or the host's clock around the run where the queue writes none.
    pub cooperative_ms: f64,
    pub tiled_ms: f64,
    /// Largest difference of the two results over the largest result.
    pub difference: f32,
    /// The kernels that ran the product in each family, where timestamps name them.
    pub cooperative_kernel: Option<&'static str>,
    pub tiled_kernel: Option<&'static str>,
}

impl MatrixUnitTrial {
    /// Whether the matrix units stay: they agree, and the tiled kernels are not [`MARGIN`] faster.
    pub fn keeps_matrix_units(&self) -> bool {
        self.agrees() && self.tiled_ms * MARGIN >= self.cooperative_ms
    }

    /// Whether the two results agree ([`AGREEMENT`]); a NaN difference never does.
    pub fn agrees(&self) -> bool {
        self.difference <= AGREEMENT
    }

    /// One line on what was chosen and why.
    pub fn summary(&self, device: &str) -> String {
        let times = format!(
            "a {M}×{N}×{K} f16 product took {:.3} ms on the matrix units, {:.3} ms on the tiled kernels",
            self.cooperative_ms, self.tiled_ms
        );
        if !self.agrees() {
            format!(
                "`{device}`: the matrix units' product differs from the tiled kernels' by {:.2e} of its size ({times}): \
                 using the tiled kernels (VKDIFF_COOPERATIVE=1 forces the matrix units)",
                self.difference
            )
        } else if self.keeps_matrix_units() {
            format!("`{device}`: {times}, results agree: using the matrix units")
        } else {
            format!(
                "`{device}`: {times}, results agree: using the tiled kernels (VKDIFF_COOPERATIVE=1 forces the matrix \
                 units)"
            )
        }
    }
}

/// max |a − b| / max |b|; NaN where the lengths differ or either holds a NaN or an infinity
/// (never agreement).
pub fn relative_difference(a: &[f32], b: &[f32]) -> f32 {
    if a.len() != b.len() || a.iter().chain(b).any(|v| !v.is_finite()) {
        return f32::NAN;
    }
    let scale = b.iter().fold(0f32, |m, v| m.max(v.abs()));
    a.iter().zip(b).fold(0f32, |m, (x, y)| m.max((x - y).abs())) / scale
}

#[cfg(test)]
mod tests {
    use super::*;

    fn trial(cooperative_ms: f64, tiled_ms: f64, difference: f32) -> MatrixUnitTrial {
        MatrixUnitTrial { cooperative_ms, tiled_ms, difference, cooperative_kernel: None, tiled_kernel: None }
    }

    #[test]
    fn the_units_stay_unless_they_disagree_or_the_tiles_are_clearly_faster() {
        assert!(trial(1.0, 4.0, 1e-3).keeps_matrix_units());
        assert!(trial(1.2, 1.0, 1e-3).keeps_matrix_units(), "within the margin");
        assert!(!trial(1.3, 1.0, 1e-3).keeps_matrix_units(), "tiles a quarter faster");
        assert!(!trial(1.0, 4.0, 0.5).keeps_matrix_units(), "garbled");
        assert!(!trial(1.0, 4.0, f32::NAN).keeps_matrix_units(), "NaN results");
    }

    #[test]
    fn differences_are_relative_and_nan_is_never_agreement() {
        assert_eq!(relative_difference(&[1.0, 2.0], &[1.0, 4.0]), 0.5);
        assert!(relative_difference(&[f32::NAN, 0.0], &[1.0, 1.0]).is_nan());
        assert!(relative_difference(&[1.0, 1.0], &[f32::INFINITY, 1.0]).is_nan());
        assert!(relative_difference(&[1.0], &[1.0, 1.0]).is_nan());
    }

    #[test]
    fn the_summary_names_the_choice() {
        assert!(trial(1.0, 4.0, 1e-3).summary("gpu").ends_with("using the matrix units"));
        assert!(trial(1.0, 4.0, 0.5).summary("gpu").contains("differs from the tiled kernels' by 5.00e-1"));
        assert!(trial(4.0, 1.0, 1e-3).summary("gpu").contains("using the tiled kernels"));
    }
}
