//! What tuning found for a shape, kept by the context it tuned.

use crate::kernel_choice::matrix_tile::MatrixTile;
use crate::kernel_choice::probe::ProbeChoice;

/// How a shape that could not be tuned (scratch memory, its settings' kernels failing) is noted.
pub(crate) const NOT_TUNED: &str = "not tuned";

/// The settings an op's kernel is chosen by: the matrix units' tile and whether it takes its
/// `VK_NV_cooperative_matrix2` probe.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct KernelPick {
    pub tile: MatrixTile,
    pub probe: ProbeChoice,
}

/// One shape as tuning found it: every distinct kernel (or kernel sequence, where the op is
/// several dispatches) with its fastest device time, and the one the shape takes.
#[derive(Clone, Debug, PartialEq)]
pub struct TunedShape {
    /// The op and its shape, as people read it ("linear 4096×640×640 + bias F16").
    pub op: String,
    /// Each candidate's kernels (variant labels, `+` between dispatches) and milliseconds.
    pub timed: Vec<(String, f64)>,
    pub chosen: usize,
    pub(crate) pick: KernelPick,
}

impl TunedShape {
    /// Whether the shape had kernels to choose between, or could not be tuned: one kernel alone
    /// is not worth a line.
    pub(crate) fn reported(&self) -> bool {
        self.timed.len() > 1 || self.timed[0].0.starts_with(NOT_TUNED)
    }

    /// The chosen candidate's kernels and milliseconds.
    pub fn winner(&self) -> (&str, f64) {
        let (kernels, ms) = &self.timed[self.chosen];
        (kernels, *ms)
    }
}
