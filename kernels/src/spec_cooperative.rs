// The kernels on the device's matrix units, beside spec.rs's (whose `KernelSpec` they use);
// included after it by build.rs and lib.rs.

/// Kernels on the device's matrix units (`VK_KHR_cooperative_matrix`), compiled in f16 only:
/// their operands are f16, so f32 products keep the scalar kernels' precision by not using
/// them. The GEMM and convolution read operands aligned to units of UW values: 8 (16-byte
/// loads) where sizes and strides are multiples of 8, else 4 (others take the tiled kernels).
/// FM×FN×FK = the fragment shape, A (FM×FK) · B (FK×FN) + C (FM×FN): 16×16×16, what NVIDIA and
/// AMD list; Intel's 8×16×16 (Xe2, 16 lanes) and 8×8×16 (Xe-HPG, 8 lanes); lavapipe's 8×8×8.
/// naga 30 spells only square fragments, so the build gives each its shape in the SPIR-V
/// (compile.rs). 8×16×16 is also built at 8 lanes: lavapipe runs it there through
/// `VK_NV_cooperative_matrix2`'s flexible dimensions, so CI proves the source Intel's 16-lane
/// variant is built from, as its 8×8×8 proves the 16×16×16 one. SG = the
/// subgroup width the workgroup's subgroups are pinned to; GM×GN = the workgroup's grid of
/// subgroups (along M and N); WM×WN = fragments of a subgroup's tile. Four subgroups (2×2) take
/// 2×2 fragments, or 4×4 for products large enough to fill a GPU with the larger tiles, where the
/// sums fit a lane's registers (built for the square fragments only). Eight subgroups take
/// K-steps of two, in three tiles the runtime chooses where asked (`VKDIFF_MATRIX_TILE`, or
/// the tuner): 2×4 of 4×2 fragments (128×128 at 16×16×16), built for every shape but AMD's 64
/// lanes, which reach 128×128 with four subgroups of 4×4, and in units of 8 only (in units of 4
/// an invocation stages twice the units, and NAK gave those up to 152 registers a lane, 160 the
/// convolution's, past the 128 that let two such workgroups share an SM; shapes off multiples
/// of 8 keep four subgroups);
/// and 4×2 or 2×4 of 2×2 fragments (128×64
/// and 64×128, the registers of the 64×64 tile's subgroups), built for NVIDIA's 16×16×16 at 32
/// lanes and lavapipe's 8×8×8 twin. KS = fragments per K-step: 4 for products, 2 for convolutions
/// (H200, measured: the convolution's tap arithmetic makes its K-step of four a third more
/// registers, 176 against 130, and it ran 1.12× slower in the UNet; products 1.3× faster).
/// Units of 8 halve the loads and the address arithmetic: ACO's `gemm_coop` loop went from 344
/// to 284 instructions, 496 to 401 with B K×N (BENCHMARKS.md).
pub const COOPERATIVE_KERNELS: &[KernelSpec] = &[
    KernelSpec {
        name: "gemm_coop",
        files: &["activations.wgsl", "gemm_common.wgsl", "a_matrix_rows.wgsl", "a_matrix_v4.wgsl", "b_matrix_v4.wgsl", "gemm_store4.wgsl", "gemm_coop.wgsl"],
        params: &[
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 4), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 4), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 4), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 4), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 4), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 4), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 4), ("WN", 4), ("BT", 0), ("GE", 0), ("KS", 4), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 4), ("WN", 4), ("BT", 0), ("GE", 0), ("KS", 4), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 4), ("WN", 4), ("BT", 1), ("GE", 0), ("KS", 4), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 4), ("WN", 4), ("BT", 1), ("GE", 0), ("KS", 4), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 4), ("WN", 4), ("BT", 1), ("GE", 1), ("KS", 4), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 4), ("WN", 4), ("BT", 1), ("GE", 1), ("KS", 4), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 4), ("UW", 4)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 4), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 4), ("UW", 4)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 4), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 4), ("UW", 4)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 4), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 64), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 4), ("UW", 4)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 64), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 4), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 64), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 4), ("UW", 4)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 64), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 4), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 64), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 4), ("UW", 4)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 64), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 4), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 64), ("GM", 2), ("GN", 2), ("WM", 4), ("WN", 4), ("BT", 0), ("GE", 0), ("KS", 4), ("UW", 4)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 64), ("GM", 2), ("GN", 2), ("WM", 4), ("WN", 4), ("BT", 0), ("GE", 0), ("KS", 4), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 64), ("GM", 2), ("GN", 2), ("WM", 4), ("WN", 4), ("BT", 1), ("GE", 0), ("KS", 4), ("UW", 4)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 64), ("GM", 2), ("GN", 2), ("WM", 4), ("WN", 4), ("BT", 1), ("GE", 0), ("KS", 4), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 64), ("GM", 2), ("GN", 2), ("WM", 4), ("WN", 4), ("BT", 1), ("GE", 1), ("KS", 4), ("UW", 4)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 64), ("GM", 2), ("GN", 2), ("WM", 4), ("WN", 4), ("BT", 1), ("GE", 1), ("KS", 4), ("UW", 8)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 16), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 4), ("UW", 4)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 16), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 4), ("UW", 8)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 16), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 4), ("UW", 4)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 16), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 4), ("UW", 8)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 16), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 4), ("UW", 4)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 16), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 4), ("UW", 8)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 4), ("UW", 4)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 4), ("UW", 8)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 4), ("UW", 4)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 4), ("UW", 8)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 4), ("UW", 4)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 4), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 4), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 4), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 4), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 4), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 4), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 4), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 16), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 16), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 16), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 2), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 4), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 4), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 4), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 4), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 4), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 2), ("UW", 4)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 4), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 2), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 4), ("WM", 2), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 4), ("WM", 2), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 4), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 4), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 4), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 2), ("UW", 4)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 4), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 4), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 4), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 4), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 4), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 4), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 4), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 2), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 2), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 2), ("UW", 8)],
        ],
    },
    KernelSpec {
        name: "conv_coop",
        files: &["activations.wgsl", "gemm_common.wgsl", "conv_taps.wgsl", "a_conv_v4.wgsl", "b_matrix_v4.wgsl", "gemm_store4.wgsl", "gemm_coop.wgsl"],
        params: &[
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 4), ("WN", 4), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 4), ("WN", 4), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 64), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 64), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 64), ("GM", 2), ("GN", 2), ("WM", 4), ("WN", 4), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 64), ("GM", 2), ("GN", 2), ("WM", 4), ("WN", 4), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 16), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 16), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 16), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 4), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 4), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 4), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 4), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 4), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 4), ("GN", 2), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 2), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
        ],
    },
    // VK_NV_cooperative_matrix2's probe of the linear rows, for `bench kernels` and
    // `VKDIFF_LINEAR=cm2`: one FM×FN accumulator a workgroup of WG invocations, of workgroup
    // scope (WS = 1, NVIDIA's drivers: ggml's 128×128 and 256×128 tiles at 256 invocations, and
    // 128×64 at 128, whichever sizes the driver offers that scope for; K-steps of 32) or of
    // subgroup scope through flexible dimensions (WS = 0: Mesa 26.1's lavapipe at 8 lanes, for
    // CI; at 16 it crashes running flexible-dimension matrices, so no 16-lane twin is built).
    // GE = 0: gemm_common.wgsl's parameters, the matrix products'.
    KernelSpec {
        name: "gemm_cm2",
        files: &["gemm_common.wgsl", "cm2_store.wgsl", "gemm_cm2.wgsl"],
        params: &[
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 8), ("WS", 0), ("WG", 8), ("GE", 0)],
            &[("FM", 128), ("FN", 128), ("FK", 32), ("SG", 32), ("WS", 1), ("WG", 256), ("GE", 0)],
            &[("FM", 256), ("FN", 128), ("FK", 32), ("SG", 32), ("WS", 1), ("WG", 256), ("GE", 0)],
            &[("FM", 128), ("FN", 64), ("FK", 32), ("SG", 32), ("WS", 1), ("WG", 128), ("GE", 0)],
        ],
    },
    // VK_NV_cooperative_matrix2's probe of the convolution, for `bench kernels` and
    // `VKDIFF_CONV=cm2`: gemm_cm2's tiles (FN = 64 too, for SDXL's 320 channels), A gathered in
    // units of UW = 8 input channels; GE = 0 (gemm_common.wgsl's parameters, conv2d's).
    KernelSpec {
        name: "conv_cm2",
        files: &["gemm_common.wgsl", "cm2_store.wgsl", "conv_taps.wgsl", "a_conv_v4.wgsl", "conv_cm2.wgsl"],
        params: &[
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 8), ("WS", 0), ("WG", 8), ("UW", 8), ("GE", 0)],
            &[("FM", 128), ("FN", 128), ("FK", 32), ("SG", 32), ("WS", 1), ("WG", 256), ("UW", 8), ("GE", 0)],
            &[("FM", 256), ("FN", 128), ("FK", 32), ("SG", 32), ("WS", 1), ("WG", 256), ("UW", 8), ("GE", 0)],
            &[("FM", 128), ("FN", 64), ("FK", 32), ("SG", 32), ("WS", 1), ("WG", 128), ("UW", 8), ("GE", 0)],
        ],
    },
    // VK_NV_cooperative_matrix2's probe of attention, for `bench kernels` and
    // `VKDIFF_ATTENTION=cm2`: FM query rows against chunks of FN keys, heads of up to FK = 64
    // values (FN ≠ FK: compile.rs would give two of the matrix types one shape), the softmax on
    // the extension's reductions and per-element operations. Workgroup scope (WS = 1) at 128 invocations for NVIDIA's drivers, within 48 KiB
    // of workgroup memory; subgroup scope at 8 lanes (Mesa 26.1's lavapipe) for CI, FM = 8: that
    // driver splits larger matrices into 8×8 pieces and, past the first band of 8 rows, reduces
    // rows from the wrong pieces (FM = 16 fails the kernel test). PV = 1: the second product;
    // PU = FN·(FK/4)/WG, attention_staging.wgsl's units per invocation.
    KernelSpec {
        name: "attention_cm2",
        files: &["attention_common.wgsl", "attention_staging.wgsl", "attention_cm2.wgsl"],
        params: &[
            &[("FM", 8), ("FN", 32), ("FK", 64), ("SG", 8), ("WS", 0), ("WG", 8), ("PV", 1), ("PU", 64)],
            &[("FM", 64), ("FN", 32), ("FK", 64), ("SG", 32), ("WS", 1), ("WG", 128), ("PV", 1), ("PU", 4)],
            &[("FM", 32), ("FN", 128), ("FK", 64), ("SG", 32), ("WS", 1), ("WG", 128), ("PV", 1), ("PU", 16)],
        ],
    },
    // The matrix units' rate with no device memory in the loop, for `bench kernels`: SRC = 0
    // operands in registers, 1 loaded from workgroup memory before each multiply-add.
    KernelSpec {
        name: "coop_ceiling",
        files: &["coop_ceiling.wgsl"],
        params: &[
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("SRC", 0)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("SRC", 1)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("SRC", 0)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("SRC", 1)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 64), ("SRC", 0)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 64), ("SRC", 1)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 16), ("SRC", 0)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 16), ("SRC", 1)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 8), ("SRC", 0)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 8), ("SRC", 1)],
            &[("FM", 8), ("FN", 8), ("FK", 16), ("SG", 8), ("SRC", 0)],
            &[("FM", 8), ("FN", 8), ("FK", 16), ("SG", 8), ("SRC", 1)],
        ],
    },
    // Attention with both products on the matrix units, heads of up to DH = 64 (SDXL's, CLIP's);
    // wider heads take attention_rows. KF = FN-wide key fragments per chunk, LPR = lanes per row
    // in the softmax (SG/FM on GPUs; 2 at 8 lanes, so that lavapipe's two passes test the
    // joined softmax). PU = KF·FN·(DH/4)/(4·SG), attention_staging.wgsl's units per invocation.
    KernelSpec {
        name: "attention_coop",
        files: &["attention_common.wgsl", "attention_operands.wgsl", "attention_staging.wgsl", "attention_coop.wgsl"],
        params: &[
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("DH", 64), ("KF", 4), ("LPR", 2), ("PU", 16)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("DH", 64), ("KF", 4), ("LPR", 2), ("PU", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 64), ("DH", 64), ("KF", 4), ("LPR", 4), ("PU", 4)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 16), ("DH", 64), ("KF", 4), ("LPR", 2), ("PU", 16)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 8), ("DH", 64), ("KF", 4), ("LPR", 2), ("PU", 32)],
            &[("FM", 8), ("FN", 8), ("FK", 16), ("SG", 8), ("DH", 64), ("KF", 4), ("LPR", 2), ("PU", 16)],
        ],
    },
];
