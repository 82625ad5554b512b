//! The device tests run on: lavapipe in CI, whatever `Context::new` picks elsewhere.

use crate::choice::{expect_cooperative, expect_cooperative_refused};
use std::sync::OnceLock;
use vkdiff_runtime::{Context, DeviceChoice, Environment, GemmFamily, MatrixTile, Settings};

/// The environment the tests run in (the CI's passes set `VKDIFF_*` variables), read once at
/// this test edge as the command line reads it at its own.
pub fn environment() -> &'static Environment {
    static ENV: OnceLock<Environment> = OnceLock::new();
    ENV.get_or_init(Environment::of_process)
}

/// The settings [`environment`] gives; a malformed one fails the test that asks.
pub fn settings() -> Settings {
    Settings::from_environment(environment()).unwrap_or_else(|e| panic!("{e}"))
}

/// The Vulkan device the tests share. No device is a failure, not a skip.
pub fn ctx() -> Context {
    static CTX: OnceLock<Context> = OnceLock::new();
    CTX.get_or_init(open).clone()
}

/// A private context on the GPU paths (`VKDIFF_GPU_PATHS=1`'s configuration: device memory
/// through staging, the GPU GEMM family, GPU attention), so every pass also runs them.
pub fn gpu_ctx() -> Context {
    static CTX: OnceLock<Context> = OnceLock::new();
    configured(&CTX, |c| c.set_gpu_paths(true))
}

/// A private context that takes the quickly compiled kernels for small products, as lavapipe
/// after Mesa 22 does by default ([`Context::quick_compile`]), so every driver tests them.
pub fn quick_ctx() -> Context {
    static CTX: OnceLock<Context> = OnceLock::new();
    configured(&CTX, |c| c.choose(|choices| choices.quick_compile = true))
}

/// The context in `cell`, opened and configured by `setup` on first use.
fn configured(cell: &OnceLock<Context>, setup: fn(&Context)) -> Context {
    cell.get_or_init(|| {
        let c = open();
        setup(&c);
        c
    })
    .clone()
}

/// A context of its own, for a test that reads its memory figures (other tests' tensors
/// would count in a shared one's).
pub fn private_ctx() -> Context {
    open()
}

/// A private context with a fixed GEMM family, so tests of both families can run in parallel.
/// Under `VKDIFF_EXPECT_COOPERATIVE=1` (the CI pass on a driver with matrix units) a device
/// whose units fit no cooperative variant fails the test instead of testing the tiled kernels twice;
/// under `=0` (a driver whose listed units vkdiff must not choose) one that lists none, or whose
/// units vkdiff chose, fails it.
pub fn ctx_with(family: GemmFamily) -> Context {
    let c = open();
    if family == GemmFamily::Cooperative && expect_cooperative() {
        let info = c.info();
        assert!(
            info.cooperative_variant().is_some(),
            "VKDIFF_EXPECT_COOPERATIVE=1, but no cooperative variant fits `{}`: {:?}",
            info.name,
            info.matrix_shapes
        );
    }
    if family == GemmFamily::Cooperative && expect_cooperative_refused() {
        let info = c.info();
        assert!(
            !info.matrix_shapes.is_empty() && info.cooperative_variant().is_none(),
            "VKDIFF_EXPECT_COOPERATIVE=0: `{}` should list matrix units and vkdiff choose none of them: {:?}, chosen {:?}",
            info.name,
            info.matrix_shapes,
            info.cooperative_variant()
        );
    }
    c.choose(|choices| choices.gemm_family = family);
    c
}

/// The matrix-unit contexts a product test runs: the cooperative family with the workgroup
/// tile `VKDIFF_MATRIX_TILE` gives, and, where the device has a matrix-unit variant, the other
/// tile too, so that every matrix-unit pass tests the kernels of both.
pub fn cooperative_ctxs() -> Vec<Context> {
    let first = ctx_with(GemmFamily::Cooperative);
    if first.info().cooperative_variant().is_none() {
        return vec![first];
    }
    let other = if first.choices().matrix_tile.eight_subgroups() { MatrixTile::Four } else { MatrixTile::Eight };
    let second = ctx_with(GemmFamily::Cooperative);
    second.choose(|c| c.matrix_tile = other);
    vec![first, second]
}

/// A matrix-unit context on each of `tiles`, where the device has a matrix-unit variant: the
/// tiles [`cooperative_ctxs`] leaves to tests of their own (choice.rs asserts that a product ran
/// in the tile where it is built for the device's fragment, in four subgroups elsewhere).
pub fn cooperative_ctxs_on(tiles: &[MatrixTile]) -> Vec<Context> {
    tiles
        .iter()
        .map_while(|&tile| {
            let ctx = ctx_with(GemmFamily::Cooperative);
            ctx.info().cooperative_variant()?;
            ctx.choose(|c| c.matrix_tile = tile);
            Some(ctx)
        })
        .collect()
}

/// A new context; under `VKDIFF_EXPECT_COOPERATIVE=1` a matrix-unit trial that dropped the units
/// fails the test, which would otherwise test the tiled kernels where the units were meant.
fn open() -> Context {
    let opened = DeviceChoice::from_environment(None, false, environment()).and_then(|d| Context::new(&d, settings()));
    let c = opened.unwrap_or_else(|e| {
        panic!(
            "vkdiff's tests need a Vulkan device and found none usable: {e}\n(on Debian: apt-get install -y \
            mesa-vulkan-drivers libvulkan1)"
        )
    });
    if let Some(trial) = c.matrix_unit_trial().filter(|t| expect_cooperative() && !t.keeps_matrix_units()) {
        panic!(
            "VKDIFF_EXPECT_COOPERATIVE=1, but the matrix units' trial dropped them: {}",
            trial.summary(&c.info().name)
        );
    }
    c
}
