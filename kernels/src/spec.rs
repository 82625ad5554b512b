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

/// A subgroup GEMM variant (kernels/wgsl/gemm_sg.wgsl) of SG lanes and TM rows, B K×N or N×K
/// (BT), GEGLU fused or not (GE), with what follows from them: AU, the rows of A each lane
/// reads (TM / SG, at least 1), and KS, the steps of 4 along K a turn: one in the 8-row variants,
/// which compile quickly; two in the 128-row ones, which 16 lanes take for tall products (at
/// four steps their turn's code ran 0.8× as fast); else four.
const fn subgroup_tile(sg: u32, tm: u32, bt: u32, ge: u32) -> [(&'static str, u32); 6] {
    let au = if tm > sg { tm / sg } else { 1 };
    let ks = match tm {
        8 => 1,
        128 => 2,
        _ => 4,
    };
    [("SG", sg), ("TM", tm), ("BT", bt), ("AU", au), ("KS", ks), ("GE", ge)]
}

/// A GroupNorm kernel: the workgroup reductions, then `files`.
macro_rules! group_norm_spec {
    ($name:literal, $($file:literal),+) => {
        KernelSpec { name: $name, files: &["reduce.wgsl", $($file),+], params: NONE }
    };
}

pub const KERNELS: &[KernelSpec] = &[
    // Register-blocked GEMM for CPU-like devices: workgroup = one subgroup, A shared by broadcasts
    // ([`subgroup_tile`]); one variant set per lavapipe width (LP_NATIVE_VECTOR_WIDTH 128, 256,
    // 512 → 4, 8, 16 lanes).
    // Every GEMM-family kernel has GE (gemm_common.wgsl): 1 fuses GEGLU into a linear layer's
    // epilogue (matrix products with B stored N×K only), 0 is the plain product.
    KernelSpec {
        name: "gemm_sg",
        files: &["activations.wgsl", "gemm_common.wgsl", "a_matrix_rows.wgsl", "a_matrix_v4.wgsl", "a_as_f32.wgsl", "gemm_store4.wgsl", "b_units.wgsl", "gemm_sg_steps.wgsl", "gemm_sg.wgsl"],
        params: &[
            &subgroup_tile(4, 8, 0, 0),
            &subgroup_tile(4, 8, 1, 0),
            &subgroup_tile(4, 8, 1, 1),
            &subgroup_tile(4, 16, 0, 0),
            &subgroup_tile(4, 16, 1, 0),
            &subgroup_tile(4, 16, 1, 1),
            &subgroup_tile(4, 32, 0, 0),
            &subgroup_tile(4, 32, 1, 0),
            &subgroup_tile(4, 32, 1, 1),
            &subgroup_tile(4, 64, 0, 0),
            &subgroup_tile(4, 64, 1, 0),
            &subgroup_tile(4, 64, 1, 1),
            &subgroup_tile(8, 8, 0, 0),
            &subgroup_tile(8, 8, 1, 0),
            &subgroup_tile(8, 8, 1, 1),
            &subgroup_tile(8, 16, 0, 0),
            &subgroup_tile(8, 16, 1, 0),
            &subgroup_tile(8, 16, 1, 1),
            &subgroup_tile(8, 32, 0, 0),
            &subgroup_tile(8, 32, 1, 0),
            &subgroup_tile(8, 32, 1, 1),
            &subgroup_tile(8, 64, 0, 0),
            &subgroup_tile(8, 64, 1, 0),
            &subgroup_tile(8, 64, 1, 1),
            &subgroup_tile(16, 8, 0, 0),
            &subgroup_tile(16, 8, 1, 0),
            &subgroup_tile(16, 8, 1, 1),
            &subgroup_tile(16, 16, 0, 0),
            &subgroup_tile(16, 16, 1, 0),
            &subgroup_tile(16, 16, 1, 1),
            &subgroup_tile(16, 32, 0, 0),
            &subgroup_tile(16, 32, 1, 0),
            &subgroup_tile(16, 32, 1, 1),
            &subgroup_tile(16, 128, 0, 0),
            &subgroup_tile(16, 128, 1, 0),
            &subgroup_tile(16, 128, 1, 1),
        ],
    },
    KernelSpec {
        name: "conv_sg",
        files: &["activations.wgsl", "gemm_common.wgsl", "conv_taps.wgsl", "a_conv_v4.wgsl", "a_as_f32.wgsl", "gemm_store4.wgsl", "b_units.wgsl", "gemm_sg_steps.wgsl", "gemm_sg.wgsl"],
        params: &[
            &subgroup_tile(4, 8, 1, 0),
            &subgroup_tile(4, 16, 1, 0),
            &subgroup_tile(4, 32, 1, 0),
            &subgroup_tile(4, 64, 1, 0),
            &subgroup_tile(8, 8, 1, 0),
            &subgroup_tile(8, 16, 1, 0),
            &subgroup_tile(8, 32, 1, 0),
            &subgroup_tile(8, 64, 1, 0),
            &subgroup_tile(16, 8, 1, 0),
            &subgroup_tile(16, 16, 1, 0),
            &subgroup_tile(16, 32, 1, 0),
            &subgroup_tile(16, 128, 1, 0),
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
    // Winograd F(2×2, 3×3)'s transforms of the input tiles, the filters and the products.
    KernelSpec { name: "winograd_input", files: &["grid.wgsl", "unit_4.wgsl", "winograd_tiles.wgsl", "winograd_input.wgsl"], params: NONE },
    KernelSpec { name: "winograd_weights", files: &["grid.wgsl", "unit_4.wgsl", "winograd_weights.wgsl"], params: NONE },
    KernelSpec { name: "winograd_output", files: &["grid.wgsl", "unit_4.wgsl", "winograd_tiles.wgsl", "winograd_output.wgsl"], params: NONE },
    KernelSpec { name: "copy_channels", files: &["grid.wgsl", "copy_channels.wgsl"], params: NONE },
    // Inception's pooling (0 max, 1 average of the taps inside) and its TensorFlow-style resize.
    KernelSpec { name: "pool2d", files: &["grid.wgsl", "pool2d.wgsl"], params: &[&[("OP", 0)], &[("OP", 1)]] },
    KernelSpec { name: "resize_tf1", files: &["grid.wgsl", "resize_tf1.wgsl"], params: NONE },
    KernelSpec { name: "timestep_embedding", files: &["timestep.wgsl"], params: NONE },
];

/// The kernels built twice, reading their operands as 32-bit words (WD = 0: an f16 unit as two
/// `u32`s, which Mesa 26.1's lavapipe loads faster than four halves) and as 64-bit words (WD = 1,
/// which lavapipe before Mesa 26, loading lane by lane, reads faster; `scalar_unit` in
/// compile.rs). Up to 8 lanes the 64-bit words need `shaderInt64`.
pub const WORD_LOADS: &[&str] = &["gemm_sg", "conv_sg", "attention"];

/// The widest subgroup whose WD = 1 variants read 64-bit words; wider ones read 32-bit words
/// there too (at 16 lanes LLVM's code for 64-bit vectors ran the products at 0.4× speed).
pub const WIDEST_64_BIT_WORDS: u32 = 8;

/// The kernels also built with B read from a uniform texel buffer (TB = 1: b_texels.wgsl in
/// place of b_units.wgsl), which lavapipe before Mesa 26 fetches without a loop over the lanes;
/// the plain products read A so too where they can (TA = 1: `texel_files` in build.rs).
pub const TEXEL_B: &[&str] = &["gemm_sg", "conv_sg"];

/// The kernels above written for GPUs only (lavapipe runs them where tests ask for the GPU paths,
/// and the tiled GEMM for shapes off the vec4 grid). They and [`COOPERATIVE_KERNELS`] are
/// compiled without naga's loop counters and index clamps (`Target` in compile.rs).
pub const GPU_KERNELS: &[&str] =
    &["gemm_tiled", "gemm_tiled_v4", "conv_tiled_v4", "attention_tiled", "attention_rows", "attention_wg"];
