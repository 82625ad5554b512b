//! The matrix units' rate with no device memory in the loop (kernels/wgsl/coop_ceiling.wgsl),
//! which `bench kernels` holds the cooperative products against.

use super::{kernel, u};
use crate::error::{ensure, Error, Result};
use crate::kernel_choice::matrix_units::Fragment;
use crate::recorder::Recorder;
use crate::tensor::{Dtype, Tensor};

/// One run of the ceiling kernel: `groups` workgroups of 4 subgroups, each adding its 2×2
/// fragment products `reps` times, the operands held in registers or (`from_shared`) loaded
/// from workgroup memory before every multiply-add, at K offset ((r·step) mod 4)·FK of step r.
#[derive(Clone, Copy, Debug)]
pub struct MatrixCeiling {
    /// The device's cooperative variant (`DeviceInfo::cooperative_variant`).
    pub fragment: Fragment,
    pub groups: usize,
    pub reps: u32,
    pub step: u32,
    pub from_shared: bool,
}

impl MatrixCeiling {
    /// Elements of the operands: A, 2·FM rows of 4·FK, then B (N×K), 2·FN rows of 4·FK, f16.
    pub fn operand_len(&self) -> usize {
        let f = &self.fragment;
        2 * (f.m + f.n) as usize * 4 * f.k as usize
    }

    /// Elements of the sums: per workgroup and subgroup, 4 fragments of FM×FN, f32.
    pub fn sums_len(&self) -> usize {
        self.groups * 4 * 4 * (self.fragment.m * self.fragment.n) as usize
    }

    /// The multiply-adds' arithmetic, 2 FLOP each.
    pub fn flops(&self) -> f64 {
        let f = &self.fragment;
        (self.groups * 4 * 4) as f64 * self.reps as f64 * 2.0 * (f.m * f.n * f.k) as f64
    }
}

/// Records the ceiling kernel on the device's cooperative variant; an error where it has none.
pub fn matrix_ceiling(rec: &mut Recorder, operands: &Tensor, sums: &Tensor, run: &MatrixCeiling) -> Result<()> {
    let ctx = rec.context().clone();
    let fragment = ctx.info().cooperative_variant().ok_or_else(|| {
        Error::Shape(format!("matrix_ceiling: device `{}` has no matrix units vkdiff's kernels fit", ctx.info().name))
    })?;
    ensure(run.fragment == fragment && run.groups > 0, || {
        format!("matrix_ceiling: {run:?} on a device of {} fragments", fragment.shape())
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
    let want: Vec<(&str, u32)> = fragment.params().into_iter().chain([("SRC", run.from_shared as u32)]).collect();
    let k = kernel(&ctx, "coop_ceiling", Dtype::F16, &want, 2)?;
    rec.dispatch(&k, &[operands], &[sums], &[run.reps, run.step], [u(run.groups), 1, 1])
}
