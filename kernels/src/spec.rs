// The kernel library's table: which WGSL files make each kernel and which variants of it are
// compiled. Included verbatim by build.rs (to compile) and by lib.rs (to name variants), so the
// two can never disagree.

/// Storage type of a kernel's tensors. Arithmetic is f32 whatever the storage.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Dtype {
    F32,
    F16,
}

/// One kernel: its sources, concatenated after a generated prelude, and the values of its
/// compile-time parameters, each list a separate variant.
pub struct KernelSpec {
    pub name: &'static str,
    pub files: &'static [&'static str],
    /// Each entry is one variant's parameter set (`const` in the prelude, `override` where naga allows).
    pub params: &'static [&'static [(&'static str, u32)]],
}

const NONE: &[&[(&str, u32)]] = &[&[]];
/// kernels/wgsl/unary.wgsl's and binary.wgsl's operations.
const UNARY: &[&[(&str, u32)]] = &[&[("OP", 0)], &[("OP", 1)], &[("OP", 2)], &[("OP", 3)], &[("OP", 4)]];
const BINARY: &[&[(&str, u32)]] = &[&[("OP", 0)], &[("OP", 1)]];

/// A GroupNorm kernel: the workgroup reductions, then `files`.
macro_rules! group_norm_spec {
    ($name:literal, $($file:literal),+) => {
        KernelSpec { name: $name, files: &["reduce.wgsl", $($file),+], params: NONE }
    };
}

pub const KERNELS: &[KernelSpec] = &[
    // Register-blocked GEMM for CPU-like devices: workgroup = one subgroup, A shared by shuffles;
    // one variant set per lavapipe width (LP_NATIVE_VECTOR_WIDTH 128, 256, 512 → 4, 8, 16 lanes).
    // Every GEMM-family kernel has GE (gemm_common.wgsl): 1 fuses GEGLU into a linear layer's
    // epilogue (matrix products with B stored N×K only), 0 is the plain product.
    KernelSpec {
        name: "gemm_sg",
        files: &["activations.wgsl", "gemm_common.wgsl", "a_matrix_rows.wgsl", "a_matrix_v4.wgsl", "a_as_f32.wgsl", "gemm_store4.wgsl", "gemm_sg.wgsl"],
        params: &[
            &[("SG", 4), ("TM", 8), ("BT", 0), ("LU", 1), ("GE", 0)],
            &[("SG", 4), ("TM", 8), ("BT", 1), ("LU", 1), ("GE", 0)],
            &[("SG", 4), ("TM", 8), ("BT", 1), ("LU", 1), ("GE", 1)],
            &[("SG", 4), ("TM", 16), ("BT", 0), ("LU", 4), ("GE", 0)],
            &[("SG", 4), ("TM", 16), ("BT", 1), ("LU", 4), ("GE", 0)],
            &[("SG", 4), ("TM", 16), ("BT", 1), ("LU", 4), ("GE", 1)],
            &[("SG", 4), ("TM", 32), ("BT", 0), ("LU", 4), ("GE", 0)],
            &[("SG", 4), ("TM", 32), ("BT", 1), ("LU", 4), ("GE", 0)],
            &[("SG", 4), ("TM", 32), ("BT", 1), ("LU", 4), ("GE", 1)],
            &[("SG", 4), ("TM", 64), ("BT", 0), ("LU", 4), ("GE", 0)],
            &[("SG", 4), ("TM", 64), ("BT", 1), ("LU", 4), ("GE", 0)],
            &[("SG", 4), ("TM", 64), ("BT", 1), ("LU", 4), ("GE", 1)],
            &[("SG", 8), ("TM", 8), ("BT", 0), ("LU", 1), ("GE", 0)],
            &[("SG", 8), ("TM", 8), ("BT", 1), ("LU", 1), ("GE", 0)],
            &[("SG", 8), ("TM", 8), ("BT", 1), ("LU", 1), ("GE", 1)],
            &[("SG", 8), ("TM", 16), ("BT", 0), ("LU", 8), ("GE", 0)],
            &[("SG", 8), ("TM", 16), ("BT", 1), ("LU", 8), ("GE", 0)],
            &[("SG", 8), ("TM", 16), ("BT", 1), ("LU", 8), ("GE", 1)],
            &[("SG", 8), ("TM", 32), ("BT", 0), ("LU", 8), ("GE", 0)],
            &[("SG", 8), ("TM", 32), ("BT", 1), ("LU", 8), ("GE", 0)],
            &[("SG", 8), ("TM", 32), ("BT", 1), ("LU", 8), ("GE", 1)],
            &[("SG", 8), ("TM", 64), ("BT", 0), ("LU", 8), ("GE", 0)],
            &[("SG", 8), ("TM", 64), ("BT", 1), ("LU", 8), ("GE", 0)],
            &[("SG", 8), ("TM", 64), ("BT", 1), ("LU", 8), ("GE", 1)],
            &[("SG", 16), ("TM", 8), ("BT", 0), ("LU", 1), ("GE", 0)],
            &[("SG", 16), ("TM", 8), ("BT", 1), ("LU", 1), ("GE", 0)],
            &[("SG", 16), ("TM", 8), ("BT", 1), ("LU", 1), ("GE", 1)],
            &[("SG", 16), ("TM", 16), ("BT", 0), ("LU", 16), ("GE", 0)],
            &[("SG", 16), ("TM", 16), ("BT", 1), ("LU", 16), ("GE", 0)],
            &[("SG", 16), ("TM", 16), ("BT", 1), ("LU", 16), ("GE", 1)],
            &[("SG", 16), ("TM", 32), ("BT", 0), ("LU", 16), ("GE", 0)],
            &[("SG", 16), ("TM", 32), ("BT", 1), ("LU", 16), ("GE", 0)],
            &[("SG", 16), ("TM", 32), ("BT", 1), ("LU", 16), ("GE", 1)],
        ],
    },
    KernelSpec {
        name: "conv_sg",
        files: &["activations.wgsl", "gemm_common.wgsl", "conv_taps.wgsl", "a_conv_v4.wgsl", "a_as_f32.wgsl", "gemm_store4.wgsl", "gemm_sg.wgsl"],
        params: &[
            &[("SG", 4), ("TM", 8), ("BT", 1), ("LU", 1), ("GE", 0)],
            &[("SG", 4), ("TM", 16), ("BT", 1), ("LU", 4), ("GE", 0)],
            &[("SG", 4), ("TM", 32), ("BT", 1), ("LU", 4), ("GE", 0)],
            &[("SG", 4), ("TM", 64), ("BT", 1), ("LU", 4), ("GE", 0)],
            &[("SG", 8), ("TM", 8), ("BT", 1), ("LU", 1), ("GE", 0)],
            &[("SG", 8), ("TM", 16), ("BT", 1), ("LU", 8), ("GE", 0)],
            &[("SG", 8), ("TM", 32), ("BT", 1), ("LU", 8), ("GE", 0)],
            &[("SG", 8), ("TM", 64), ("BT", 1), ("LU", 8), ("GE", 0)],
            &[("SG", 16), ("TM", 8), ("BT", 1), ("LU", 1), ("GE", 0)],
            &[("SG", 16), ("TM", 16), ("BT", 1), ("LU", 16), ("GE", 0)],
            &[("SG", 16), ("TM", 32), ("BT", 1), ("LU", 16), ("GE", 0)],
        ],
    },
    // Shared-memory tiled GEMM: any shape; GPUs without matrix units, and f32 products on any GPU.
    KernelSpec {
        name: "gemm_tiled",
        files: &["activations.wgsl", "gemm_common.wgsl", "a_matrix_rows.wgsl", "a_matrix.wgsl", "gemm_store.wgsl", "gemm_tiled.wgsl"],
        params: &[&[("BT", 0), ("GE", 0)], &[("BT", 1), ("GE", 0)], &[("BT", 1), ("GE", 1)]],
    },
    // The same for vec4-aligned operands, RH·32 outputs an invocation in tiles of 64·RH × 128.
    // GEGLU follows the product on GPUs (gemm.rs, `linear_geglu`), so no GE = 1 variant is built.
    KernelSpec {
        name: "gemm_tiled_v4",
        files: &[
            "activations.wgsl",
            "gemm_common.wgsl",
            "a_matrix_rows.wgsl",
            "a_matrix_v4.wgsl",
            "b_matrix_v4.wgsl",
            "gemm_store4.wgsl",
            "gemm_tiled_v4.wgsl",
        ],
        params: &[
            &[("BT", 0), ("GE", 0), ("RH", 1)],
            &[("BT", 0), ("GE", 0), ("RH", 2)],
            &[("BT", 1), ("GE", 0), ("RH", 1)],
            &[("BT", 1), ("GE", 0), ("RH", 2)],
        ],
    },
    KernelSpec {
        name: "conv_tiled_v4",
        files: &[
            "activations.wgsl",
            "gemm_common.wgsl",
            "conv_taps.wgsl",
            "a_conv_v4.wgsl",
            "b_matrix_v4.wgsl",
            "gemm_store4.wgsl",
            "gemm_tiled_v4.wgsl",
        ],
        params: &[&[("BT", 1), ("GE", 0), ("RH", 1)], &[("BT", 1), ("GE", 0), ("RH", 2)]],
    },
    // GroupNorm, one, two (`_v2`) or four (`_v4`) channels a step (unit_*.wgsl): in one
    // workgroup per group, or in bands (statistics, then the normalisation) on GPUs and past the
    // binding limit.
    group_norm_spec!("group_norm", "unit_1.wgsl", "group_moments.wgsl", "group_apply.wgsl", "group_norm.wgsl"),
    group_norm_spec!("group_norm_v2", "unit_2.wgsl", "group_moments.wgsl", "group_apply.wgsl", "group_norm.wgsl"),
    group_norm_spec!("group_norm_v4", "unit_4.wgsl", "group_moments.wgsl", "group_apply.wgsl", "group_norm.wgsl"),
    group_norm_spec!("group_norm_stats", "unit_1.wgsl", "group_moments.wgsl", "group_norm_stats.wgsl"),
    group_norm_spec!("group_norm_stats_v2", "unit_2.wgsl", "group_moments.wgsl", "group_norm_stats.wgsl"),
    group_norm_spec!("group_norm_stats_v4", "unit_4.wgsl", "group_moments.wgsl", "group_norm_stats.wgsl"),
    group_norm_spec!("group_norm_apply", "unit_1.wgsl", "group_apply.wgsl", "group_norm_apply.wgsl"),
    group_norm_spec!("group_norm_apply_v2", "unit_2.wgsl", "group_apply.wgsl", "group_norm_apply.wgsl"),
    group_norm_spec!("group_norm_apply_v4", "unit_4.wgsl", "group_apply.wgsl", "group_norm_apply.wgsl"),
    KernelSpec { name: "layer_norm", files: &["reduce.wgsl", "layer_norm.wgsl"], params: NONE },
    KernelSpec { name: "layer_norm_v4", files: &["layer_norm_v4.wgsl"], params: NONE },
    KernelSpec { name: "softmax", files: &["reduce.wgsl", "softmax.wgsl"], params: NONE },
    // Flash attention; DV = vec4 slots of the head per lane, TM = query rows per workgroup. The
    // subgroup variants cover lavapipe's widths; `attention_wg` every other width and head size.
    KernelSpec {
        name: "attention",
        files: &["attention_common.wgsl", "attention_operands.wgsl", "attention.wgsl"],
        params: &[
            &[("SG", 4), ("DV", 1), ("TM", 16)],
            &[("SG", 4), ("DV", 2), ("TM", 16)],
            &[("SG", 4), ("DV", 4), ("TM", 8)],
            &[("SG", 8), ("DV", 1), ("TM", 16)],
            &[("SG", 8), ("DV", 2), ("TM", 16)],
            &[("SG", 8), ("DV", 4), ("TM", 8)],
            &[("SG", 8), ("DV", 8), ("TM", 4)],
            &[("SG", 8), ("DV", 16), ("TM", 4)],
            &[("SG", 16), ("DV", 1), ("TM", 8)],
            &[("SG", 16), ("DV", 2), ("TM", 8)],
            &[("SG", 16), ("DV", 4), ("TM", 4)],
            &[("SG", 16), ("DV", 8), ("TM", 4)],
        ],
    },
    // GPU attention, one query row per invocation: DS = vec4 slots of the head, KC = keys per
    // chunk in workgroup memory (2·KC·DS vec4s: 32 KiB at most).
    KernelSpec {
        name: "attention_rows",
        files: &["attention_common.wgsl", "attention_operands.wgsl", "attention_rows.wgsl"],
        params: &[&[("DS", 16), ("KC", 64)], &[("DS", 32), ("KC", 32)]],
    },
    // GPU attention for heads of up to 64 values, 4×4 scores and outputs an invocation: TM = 64
    // query rows per workgroup of 16×16.
    KernelSpec { name: "attention_tiled", files: &["attention_common.wgsl", "attention_operands.wgsl", "attention_tiled.wgsl"], params: &[&[("TM", 64)]] },
    // Workgroup-memory attention: W invocations, no subgroup operations.
    KernelSpec {
        name: "attention_wg",
        files: &["attention_common.wgsl", "attention_operands.wgsl", "attention_wg.wgsl"],
        params: &[
            &[("W", 64), ("DV", 1), ("TM", 8)],
            &[("W", 64), ("DV", 2), ("TM", 4)],
            &[("W", 64), ("DV", 4), ("TM", 2)],
        ],
    },
    // Element-wise kernels, each as one value per invocation and as a vec4 (`_v4`, unit_4.wgsl).
    KernelSpec { name: "unary", files: &["grid.wgsl", "activations.wgsl", "unit_1.wgsl", "unary.wgsl"], params: UNARY },
    KernelSpec {
        name: "unary_v4",
        files: &["grid.wgsl", "activations.wgsl", "unit_4.wgsl", "unary.wgsl"],
        params: UNARY,
    },
    KernelSpec { name: "binary", files: &["grid.wgsl", "unit_1.wgsl", "binary.wgsl"], params: BINARY },
    KernelSpec { name: "binary_v4", files: &["grid.wgsl", "unit_4.wgsl", "binary.wgsl"], params: BINARY },
    KernelSpec { name: "geglu", files: &["grid.wgsl", "activations.wgsl", "unit_1.wgsl", "geglu.wgsl"], params: NONE },
    KernelSpec {
        name: "geglu_v4",
        files: &["grid.wgsl", "activations.wgsl", "unit_4.wgsl", "geglu.wgsl"],
        params: NONE,
    },
    KernelSpec { name: "upsample_nearest2x", files: &["grid.wgsl", "unit_1.wgsl", "upsample.wgsl"], params: NONE },
    KernelSpec { name: "upsample_nearest2x_v4", files: &["grid.wgsl", "unit_4.wgsl", "upsample.wgsl"], params: NONE },
    KernelSpec { name: "concat_channels", files: &["grid.wgsl", "unit_1.wgsl", "concat.wgsl"], params: NONE },
    KernelSpec { name: "concat_channels_v4", files: &["grid.wgsl", "unit_4.wgsl", "concat.wgsl"], params: NONE },
    KernelSpec { name: "copy_heads", files: &["grid.wgsl", "heads_as_stored.wgsl", "copy_heads.wgsl"], params: NONE },
    // f16 heads widened for f32 arithmetic and the results narrowed back (wide attention heads).
    KernelSpec { name: "copy_heads_to_f32", files: &["grid.wgsl", "heads_to_f32.wgsl", "copy_heads.wgsl"], params: NONE },
    KernelSpec {
        name: "copy_heads_from_f32",
        files: &["grid.wgsl", "heads_from_f32.wgsl", "copy_heads.wgsl"],
        params: NONE,
    },
    KernelSpec { name: "copy_channels", files: &["grid.wgsl", "copy_channels.wgsl"], params: NONE },
    // Inception's pooling (0 max, 1 average of the taps inside) and its TensorFlow-style resize.
    KernelSpec { name: "pool2d", files: &["grid.wgsl", "pool2d.wgsl"], params: &[&[("OP", 0)], &[("OP", 1)]] },
    KernelSpec { name: "resize_tf1", files: &["grid.wgsl", "resize_tf1.wgsl"], params: NONE },
    KernelSpec { name: "timestep_embedding", files: &["timestep.wgsl"], params: NONE },
];

/// The kernels above written for GPUs only (lavapipe runs them where tests ask for the GPU paths,
/// and the tiled GEMM for shapes off the vec4 grid). They and [`COOPERATIVE_KERNELS`] are
/// compiled without naga's loop counters and index clamps (`Target` in compile.rs).
pub const GPU_KERNELS: &[&str] =
    &["gemm_tiled", "gemm_tiled_v4", "conv_tiled_v4", "attention_tiled", "attention_rows", "attention_wg"];

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
/// lanes, which reach 128×128 with four subgroups of 4×4; and 4×2 or 2×4 of 2×2 fragments (128×64
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
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 2), ("UW", 4)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 16), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 16), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 16), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 16), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 16), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 16), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 0), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 1), ("KS", 2), ("UW", 4)],
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
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 16), ("FN", 16), ("FK", 16), ("SG", 32), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 8), ("FK", 8), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 16), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 16), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
            &[("FM", 8), ("FN", 16), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 8)],
            &[("FM", 8), ("FN", 8), ("FK", 16), ("SG", 8), ("GM", 2), ("GN", 4), ("WM", 4), ("WN", 2), ("BT", 1), ("GE", 0), ("KS", 2), ("UW", 4)],
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
