//! The matrix units' rate with no device memory in the loop (kernels/wgsl/coop_ceiling.wgsl),
//! which `bench kernels` holds the cooperative products against.

use super::{kernel, u};
use crate::error::{ensure, Error, Result};
use crate::recorder::Recorder;
use crate::tensor::{Dtype, Tensor};

/// One run of the ceiling kernel: `groups` workgroups of 4 subgroups, each adding its 2×2
/// fragment products `reps` times, the operands held in registers or (`from_shared`) loaded
/// from workgroup memory before every multiply-add, at K offset ((r·step) mod 4)·CM of step r.
#[derive(Clone, Copy, Debug)]
pub struct MatrixCeiling {
    /// The device's fragment size (8 on lavapipe, 16 on NVIDIA and AMD).
    pub fragment: usize,
    pub groups: usize,
    pub reps: u32,
    pub step: u32,
    pub from_shared: bool,
}

impl MatrixCeiling {
    /// Elements of the operands: A, 2·CM rows of 4·CM, then B (N×K) alike, f16.
    pub fn operand_len(&self) -> usize {
        4 * self.fragment * 4 * self.fragment
    }

    /// Elements of the sums: per workgroup and subgroup, 4 fragments of CM×CM, f32.
    pub fn sums_len(&self) -> usize {
        self.groups * 4 * 4 * self.fragment * self.fragment
    }

    /// The multiply-adds' arithmetic, 2 FLOP each.
    pub fn flops(&self) -> f64 {
        (self.groups * 4 * 4) as f64 * self.reps as f64 * 2.0 * (self.fragment as f64).powi(3)
    }
}

/// Records the ceiling kernel on the device's cooperative variant; an error where it has none.
pub fn matrix_ceiling(rec: &mut Recorder, operands: &Tensor, sums: &Tensor, run: &MatrixCeiling) -> Result<()> {
    let ctx = rec.context().clone();
    let (cm, sg) = ctx.info().cooperative_variant().ok_or_else(|| {
        Error::Shape(format!("matrix_ceiling: device `{}` has no matrix units vkdiff's kernels fit", ctx.info().name))
    })?;
    ensure(run.fragment == cm as usize && run.groups > 0, || {
        format!("matrix_ceiling: {run:?} on a device of {cm}×{cm} fragments")
    })?;
    ensure(operands.dtype() == Dtype::F16 && operands.numel() >= run.operand_len(), || {
        format!(
            "matrix_ceiling: operands {:?} {:?}, need {} f16",
            operands.shape(),
            operands.dtype(),
            run.operand_len()
        )
    })?;
    ensure(sums.dtype() == Dtype::F32 && sums.numel() >= run.sums_len(), || {
        format!("matrix_ceiling: sums {:?} {:?}, need {} f32", sums.shape(), sums.dtype(), run.sums_len())
    })?;
    rec.count_flops(run.flops());
    let want = [("CM", cm), ("SG", sg), ("SRC", run.from_shared as u32)];
    let k = kernel(&ctx, "coop_ceiling", Dtype::F16, &want, 2)?;
    rec.dispatch(&k, &[operands], &[sums], &[run.reps, run.step], [u(run.groups), 1, 1])
}
