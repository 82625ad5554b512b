//! What the ops on `VK_NV_cooperative_matrix2`'s probes share: the check that a device runs a
//! tile, and the tile an op takes where the context asks for its probe.

use crate::context::Context;
use crate::error::{Error, Result};
use crate::kernel_choice::matrix2_tile::{Matrix2Probe, Matrix2Tile};
use crate::kernel_choice::probe::ProbeChoice;
use crate::tensor::Dtype;

/// An error unless `tile` is one of `probe`'s that the context's device runs.
pub(super) fn ensure_offered(ctx: &Context, op: &str, probe: Matrix2Probe, tile: &Matrix2Tile) -> Result<()> {
    match tile.probe == probe && ctx.info().matrix2_tiles().contains(tile) {
        true => Ok(()),
        false => Err(Error::Shape(format!(
            "{op}: device `{}` does not run the VK_NV_cooperative_matrix2 tile {}",
            ctx.info().name,
            tile.label()
        ))),
    }
}

/// The tile of `probe` an op takes where its setting (`choice`) asks for the probe and its
/// tensors are f16: the first the device runs that `fits` the op's shape.
pub(super) fn asked_tile(
    ctx: &Context,
    choice: ProbeChoice,
    dtype: Dtype,
    probe: Matrix2Probe,
    fits: impl Fn(&Matrix2Tile) -> bool,
) -> Option<Matrix2Tile> {
    if choice != ProbeChoice::Matrix2 || dtype != Dtype::F16 {
        return None;
    }
    ctx.info().matrix2_tiles().into_iter().find(|t| t.probe == probe && fits(t))
}
