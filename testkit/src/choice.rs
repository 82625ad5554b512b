//! What a test asserts of the kernels that ran (`Context::run_listing`, `Recording::variants`):
//! the family its context takes for the products, with, on the matrix units, the fragment shape
//! the device runs (`VKDIFF_FRAGMENT`'s where asked) and the workgroup tile the context asks
//! for (`VKDIFF_MATRIX_TILE`), or VK_NV_cooperative_matrix2's linear product and convolution
//! where `VKDIFF_LINEAR=cm2` and `VKDIFF_CONV=cm2` ask for them; and attention on the matrix
//! units (in the products' fragment shape) where the CI pass of a driver with them says it must,
//! or on VK_NV_cooperative_matrix2's probe where `VKDIFF_ATTENTION=cm2` asks for it. A regressed selection then fails the test
//! instead of passing on another kernel.

use crate::device::environment;
use vkdiff_runtime::{Context, Dtype, Fragment, GemmFamily, Matrix2Probe, ProbeChoice, Variant};

/// Whether the CI pass runs on a driver whose matrix units must be used.
pub fn expect_cooperative() -> bool {
    expected_cooperative() == Some(true)
}

/// Whether the CI pass runs on a driver that lists matrix units vkdiff must not choose
/// (`VKDIFF_EXPECT_COOPERATIVE=0`: Mesa 26.1's lavapipe at 16 lanes, which crashed running them).
pub fn expect_cooperative_refused() -> bool {
    expected_cooperative() == Some(false)
}

/// `VKDIFF_EXPECT_COOPERATIVE`, a switch.
fn expected_cooperative() -> Option<bool> {
    environment().switch("VKDIFF_EXPECT_COOPERATIVE").unwrap_or_else(|e| panic!("{e}"))
}

/// `VKDIFF_FRAGMENT=MxNxK` as the CI passes for Intel's shapes set it, read here apart from the
/// runtime's own parser, so that a runtime that ignored it fails.
fn asked_fragment() -> Option<[u32; 3]> {
    let text = environment().get("VKDIFF_FRAGMENT")?;
    let sides: Vec<u32> = text.split('x').map(|n| n.parse().expect("VKDIFF_FRAGMENT as MxNxK")).collect();
    Some(sides.try_into().expect("VKDIFF_FRAGMENT as MxNxK"))
}

/// Whether the context takes VK_NV_cooperative_matrix2's probe for `op` where it fits: its
/// setting, or `variable` (`VKDIFF_ATTENTION`, `VKDIFF_LINEAR`, `VKDIFF_CONV`) read here too, so that a runtime
/// that ignored it fails.
fn probe_asked(setting: ProbeChoice, variable: &str) -> bool {
    setting == ProbeChoice::Matrix2 || environment().get(variable).is_some_and(|v| v.eq_ignore_ascii_case("cm2"))
}

/// The probe kernels `ctx` takes for f16 products its tiles fit (`gemm_cm2`, `conv_cm2`), as
/// `VKDIFF_LINEAR` and `VKDIFF_CONV` ask for them.
fn product_probes_due(ctx: &Context, dtype: Dtype) -> Vec<&'static str> {
    let offered = |probe| ctx.info().matrix2_tiles().iter().any(|t| t.probe == probe);
    let asked = [
        ("gemm_cm2", Matrix2Probe::Linear, probe_asked(ctx.choices().linear, "VKDIFF_LINEAR")),
        ("conv_cm2", Matrix2Probe::Conv, probe_asked(ctx.choices().conv, "VKDIFF_CONV")),
    ];
    let due = asked.into_iter().filter(|&(_, probe, asked)| asked && offered(probe) && dtype == Dtype::F16);
    due.map(|(kernel, ..)| kernel).collect()
}

fn names(variants: &[&Variant]) -> Vec<String> {
    variants.iter().map(|v| format!("{}{:?}", v.kernel, v.params)).collect()
}

/// The family name a product kernel belongs to: `_coop`, `_tiled` (`gemm_tiled_v4` too) or `_sg`.
fn family_of(kernel: &str) -> Option<&'static str> {
    ["_coop", "_tiled", "_sg"].into_iter().find(|f| kernel.contains(f))
}

/// The product family `ctx` takes for `dtype`: `_coop`, `_sg` or `_tiled`.
fn due_family(ctx: &Context, dtype: Dtype) -> &'static str {
    match (ctx.choices().gemm_family, dtype, ctx.info().cooperative_variant()) {
        (GemmFamily::Cooperative, Dtype::F16, Some(_)) => "_coop",
        (GemmFamily::Subgroup, _, _) => "_sg",
        _ => "_tiled",
    }
}

/// Asserts that a matrix-unit kernel (`_coop`) ran in the fragment shape the device runs, and in
/// `VKDIFF_FRAGMENT`'s where asked; returns that fragment.
fn assert_fragment(ctx: &Context, v: &Variant, what: &str) -> Fragment {
    let f = ctx.info().cooperative_variant().expect("a matrix-unit kernel on a device with a fragment");
    let shape = [v.param("FM"), v.param("FN"), v.param("FK")];
    assert_eq!(shape, [Some(f.m), Some(f.n), Some(f.k)], "{what}: {} in the device's fragment", v.kernel);
    if let Some(asked) = asked_fragment() {
        assert_eq!(shape, asked.map(Some), "{what}: {} in VKDIFF_FRAGMENT's shape", v.kernel);
    }
    f
}

/// Asserts that every product (GEMM or convolution) in `variants` ran on the family `ctx` takes
/// for `dtype`, or on VK_NV_cooperative_matrix2's probes where `VKDIFF_LINEAR=cm2` or
/// `VKDIFF_CONV=cm2` asks for them; with `fallback`, a shape the family cannot take (off the
/// vec4 grid) may run on the tiled kernels instead. Returns the products' variants.
pub fn assert_product_family<'a>(
    ctx: &Context,
    dtype: Dtype,
    variants: &[&'a Variant],
    what: &str,
    fallback: bool,
) -> Vec<&'a Variant> {
    let products: Vec<&Variant> =
        variants.iter().copied().filter(|v| v.kernel.starts_with("gemm_") || v.kernel.starts_with("conv_")).collect();
    assert!(!products.is_empty(), "{what}: no product kernel ran: {:?}", names(variants));
    let expected = due_family(ctx, dtype);
    let probes = product_probes_due(ctx, dtype);
    for v in &products {
        if v.kernel.ends_with("_cm2") {
            assert!(probes.contains(&v.kernel), "{what}: {} ran unasked (VKDIFF_LINEAR, VKDIFF_CONV)", v.kernel);
            continue;
        }
        let family = family_of(v.kernel);
        let allowed = family == Some(expected) || fallback && family == Some("_tiled");
        assert!(allowed, "{what}: {:?} ran {} where {expected} was due", ctx.choices().gemm_family, v.kernel);
        if family == Some("_coop") {
            let f = assert_fragment(ctx, v, what);
            // The setting's eight-subgroup grid where this kernel has it built in the unit it ran
            // in, else four subgroups.
            let grid = ctx.choices().matrix_tile.eight_subgroup_grid();
            let unit = [("UW", v.param("UW").expect("a matrix-unit kernel's unit"))];
            let built = grid.filter(|g| {
                vkdiff_kernels::find(v.kernel, Dtype::F16, &[&f.params()[..], g, &unit].concat()).is_some()
            });
            let ran = |name| v.param(name).unwrap_or(0);
            match built {
                Some(grid) => {
                    let want = grid.map(|(name, value)| (name, Some(value)));
                    assert_eq!(grid.map(|(name, _)| (name, v.param(name))), want, "{what}: {} in its tile", v.kernel);
                }
                None => assert_eq!(ran("GM") * ran("GN"), 4, "{what}: {} in workgroups of 4 subgroups", v.kernel),
            }
        }
    }
    if expected == "_coop" && expect_cooperative() && !fallback {
        let on_units = |v: &&Variant| v.kernel.ends_with("_coop") || v.kernel.ends_with("_cm2");
        assert!(products.iter().all(on_units), "{what}: {:?}", names(&products));
    }
    products
}

/// Asserts attention's kernel where the choice is certain: `attention_cm2` for f16 heads of up to
/// 64 where `VKDIFF_ATTENTION=cm2` asks for it and the device runs it; on the matrix units for
/// such heads on a GPU-path context with them, in the CI pass that expects them; `attention_tiled`
/// for such heads on GPU paths without them (f32, or no units). Contexts that take the quickly
/// compiled kernels run `attention_wg` instead. Attention on the matrix units, wherever it ran,
/// in the fragment shape the products take.
pub fn assert_attention_kernel(ctx: &Context, dtype: Dtype, head_dim: usize, variants: &[&Variant], what: &str) {
    for v in variants.iter().filter(|v| v.kernel == "attention_coop") {
        assert_fragment(ctx, v, what);
    }
    let kernels: Vec<&str> = variants.iter().map(|v| v.kernel).collect();
    let asked = probe_asked(ctx.choices().attention, "VKDIFF_ATTENTION");
    let matrix2 = ctx.info().matrix2_tiles().iter().any(|t| t.probe == Matrix2Probe::Attention);
    if asked && matrix2 && dtype == Dtype::F16 && head_dim <= 64 {
        assert!(
            kernels.contains(&"attention_cm2"),
            "{what}: VKDIFF_ATTENTION=cm2, heads of {head_dim} ran {kernels:?}"
        );
        return;
    }
    if !ctx.choices().gpu_paths || ctx.choices().quick_compile || head_dim > 64 {
        return;
    }
    let units = ctx.choices().gemm_family == GemmFamily::Cooperative && ctx.info().cooperative_variant().is_some();
    if units && dtype == Dtype::F16 {
        if expect_cooperative() {
            assert!(kernels.contains(&"attention_coop"), "{what}: f16 heads of {head_dim} ran {kernels:?}");
        }
    } else if dtype == Dtype::F32 || !units {
        assert!(kernels.contains(&"attention_tiled"), "{what}: heads of {head_dim} ran {kernels:?}");
    }
}

/// Asserts the products and attention of a whole network's recordings (`listing_variants`):
/// every product on the family `ctx` takes for `dtype` or, for a layer off the vec4 grid, the
/// tiled kernels, and at least one on that family or, where `VKDIFF_LINEAR=cm2` or
/// `VKDIFF_CONV=cm2` asks for VK_NV_cooperative_matrix2's probes, on them; where the network has
/// convolutions, at least one product on each probe asked for; attention, where the
/// network has any, as [`assert_attention_kernel`] says for heads of up to `head_dim`.
pub fn assert_network_kernels(ctx: &Context, dtype: Dtype, variants: &[&Variant], head_dim: usize, what: &str) {
    let products = assert_product_family(ctx, dtype, variants, what, true);
    let due = due_family(ctx, dtype);
    let probes = product_probes_due(ctx, dtype);
    assert!(
        products.iter().any(|v| family_of(v.kernel) == Some(due) || probes.contains(&v.kernel)),
        "{what}: no product ran on {due}: {:?}",
        names(&products)
    );
    let kernels: Vec<&str> = variants.iter().map(|v| v.kernel).collect();
    // Only networks with convolutions are held to the linear probe too: their linear layers over
    // pixels have rows the tiles fit, where a text encoder's 77 tokens fit none.
    if kernels.iter().any(|k| k.starts_with("conv_")) {
        for probe in probes {
            assert!(kernels.contains(&probe), "{what}: {probe} asked for, the products ran {kernels:?}");
        }
    }
    // Networks without attention (the small ControlNet) have no choice of it to assert.
    if kernels.iter().any(|k| k.starts_with("attention")) {
        assert_attention_kernel(ctx, dtype, head_dim, variants, what);
    }
}
