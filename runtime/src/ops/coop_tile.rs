//! The workgroup tile of the matrix-unit GEMM and convolution (`gemm_coop.wgsl`): how many
//! subgroups share it and how many fragments each holds, per device, product and
//! `VKDIFF_MATRIX_TILE`.

use super::gemm_family::GemmShape;
use crate::context::Context;
use crate::device::DeviceKind;
use crate::kernel_choice::matrix_tile::MatrixTile;
use crate::kernel_choice::matrix_units::Fragment;
use crate::tensor::Dtype;

/// A matrix-unit workgroup's tile: a `down`×`across` grid of subgroups, each `rows`×`cols`
/// fragments (GM, GN, WM and WN in kernels/src/spec_cooperative.rs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct CoopTile {
    down: u32,
    across: u32,
    rows: u32,
    cols: u32,
}

impl CoopTile {
    pub(super) fn params(&self) -> [(&'static str, u32); 4] {
        [("GM", self.down), ("GN", self.across), ("WM", self.rows), ("WN", self.cols)]
    }

    /// Rows and columns of C a workgroup computes.
    pub(super) fn size(&self, f: &Fragment) -> (usize, usize) {
        ((self.down * self.rows * f.m) as usize, (self.across * self.cols * f.n) as usize)
    }
}

/// The cooperative kernels' tile for a product: the eight-subgroup tile `setting` asks for
/// ([`crate::MatrixTile`]: the context's, or the tuner's) where a variant of it is built with
/// `params` (the variant parameters besides the tile's: B's layout, GEGLU, the unit); else four
/// subgroups of 4×4 fragments (tiles of 8·FM × 8·FN) where such a variant is built, the product
/// still makes 128 such tiles, enough to keep a GPU's 100+ compute units busy, and the accumulators fit a GPU
/// lane's registers (at most 64 f32 each: 16×16 fragments on 64-lane subgroups); else four of
/// 2×2. At 32 lanes 4×4 fragments take 128 registers a lane for the sums alone, and NVIDIA's
/// compiler then spilled (H200: 255 registers, the products 1.5× slower than 2×2). CPU devices
/// (lavapipe's 8×8×8 kernels) have no register file to fill and take both sizes.
pub(super) fn cooperative_tile(
    ctx: &Context,
    setting: MatrixTile,
    s: &GemmShape,
    f: &Fragment,
    kernel: &str,
    params: &[(&str, u32)],
) -> CoopTile {
    let built = |tile: CoopTile| {
        let want: Vec<(&str, u32)> =
            f.params().into_iter().chain(tile.params()).chain(params.iter().copied()).collect();
        vkdiff_kernels::find(kernel, Dtype::F16, &want).is_some()
    };
    if let Some([(_, down), (_, across), (_, rows), (_, cols)]) = setting.eight_subgroup_grid() {
        let eight = CoopTile { down, across, rows, cols };
        if built(eight) {
            return eight;
        }
    }
    let large = CoopTile { down: 2, across: 2, rows: 4, cols: 4 };
    let fills = s.m.div_ceil(8 * f.m as usize) * s.n.div_ceil(8 * f.n as usize) * s.batch >= 128;
    let fits = 16 * f.m * f.n / f.lanes <= 64 || ctx.info().kind == DeviceKind::Cpu;
    if fills && fits && built(large) {
        large
    } else {
        CoopTile { down: 2, across: 2, rows: 2, cols: 2 }
    }
}
