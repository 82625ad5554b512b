//! Arithmetic peaks of known GPUs, to give a measured rate as a share of what the device can do.

use vkdiff_runtime::{Context, DeviceKind, Dtype, GemmFamily, MatrixTile};

/// Dense peaks in TFLOP/s from the vendors' datasheets (boost clock, without sparsity): f16 on
/// the matrix units with f32 accumulation, and f32 on the SIMT cores. Matched by a substring of
/// the Vulkan device name, first match wins (the NVL and PCIe parts come before their SXM ones).
const KNOWN: &[(&str, f64, f64)] = &[
    ("H200 NVL", 835.0, 60.0),
    ("H200", 989.0, 67.0),
    ("H100 NVL", 835.0, 60.0),
    ("H100 PCIe", 756.0, 51.0),
    ("H100", 989.0, 67.0),
    ("A100", 312.0, 19.5),
    ("RTX 4090", 165.2, 82.6),
    ("RTX 3090", 71.0, 35.6),
    ("RX 7900 XTX", 122.8, 61.4),
];

/// The f16 matrix-unit peak of this device in FLOP/s, where it is a GPU in the table.
pub(crate) fn matrix_peak(ctx: &Context) -> Option<f64> {
    let info = ctx.info();
    if info.kind == DeviceKind::Cpu {
        return None;
    }
    KNOWN.iter().find(|(name, ..)| info.name.contains(name)).map(|&(_, matrix, _)| matrix * 1e12)
}

/// "12.3 %" of the matrix peak, "unknown" for a GPU not in the table, "-" on CPU devices
/// (lavapipe emulates the matrix units: its figures prove correctness, not speed).
pub(crate) fn share_label(ctx: &Context, flops_per_s: f64) -> String {
    match matrix_peak(ctx) {
        Some(peak) => format!("{:.1} %", 100.0 * flops_per_s / peak),
        None if ctx.info().kind == DeviceKind::Cpu => "-".into(),
        None => "unknown".into(),
    }
}

/// The GEMM/convolution kernels a product in `dtype` runs on with the context's family now.
pub(crate) fn family_label(ctx: &Context, dtype: Dtype) -> String {
    match (ctx.choices().gemm_family, ctx.info().cooperative_variant()) {
        (GemmFamily::Cooperative, Some(f)) if dtype == Dtype::F16 => {
            let tile = ctx.choices().matrix_tile;
            let eight = match tile {
                _ if !tile.built_for(&f) => String::new(),
                MatrixTile::Eight => ", 8 SG".into(),
                _ => format!(", 8 SG {}", tile.name()),
            };
            format!("matrix units {}{eight}", f.shape())
        }
        (GemmFamily::Subgroup, _) => "subgroup-register".into(),
        _ => "tiled".into(),
    }
}

/// What the matrix units' trial at the context's start found and chose, where one ran.
pub(crate) fn trial_label(ctx: &Context) -> Option<String> {
    ctx.matrix_unit_trial().map(|t| t.summary(&ctx.info().name))
}

/// Whether the device has matrix units vkdiff's kernels fit and `VKDIFF_COOPERATIVE=0` leaves
/// them on, whether or not the trial kept them: benchmarks time them either way.
pub(crate) fn has_matrix_units(ctx: &Context) -> bool {
    ctx.plan().fragment.is_some()
}
