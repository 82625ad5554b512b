//! Every kernel against an f64 CPU reference on the Vulkan device (lavapipe in CI), for f32 and
//! f16 storage, with the tolerance each test states.

mod attention;
mod attention_cm2;
mod bands;
mod ceiling;
mod conv;
mod conv_cm2;
mod elementwise;
mod gemm;
mod linear_cm2;
mod matrix_unit_trial;
mod norm;
mod pool;
mod runtime;
mod tuning;
mod winograd;

/// The tallest subgroup GEMM tile the shared context takes: 32 rows where small products take the
/// quickly compiled variants (lavapipe after Mesa 22, whose JIT takes minutes at 64 rows), else
/// 128 at 16 lanes and 64 at fewer.
fn tallest_subgroup_rows() -> u32 {
    let ctx = vkdiff_testkit::ctx();
    match (ctx.choices().quick_compile, ctx.info().gemm_subgroup_width()) {
        (true, _) => 32,
        (false, Some(16)) => 128,
        (false, _) => 64,
    }
}
