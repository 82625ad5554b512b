//! What vkdiff's tests share, as a dev-dependency of every crate: the Vulkan device (no device is
//! a failure that says what to install, never a skip), deterministic data, the repository's
//! fixture paths, scratch folders, and comparisons that name the worst element.

mod choice;
mod compare;
mod device;
mod paths;

pub use choice::{assert_attention_kernel, assert_network_kernels, assert_product_family, expect_cooperative};
pub use compare::{assert_close, assert_within, random, storage_rtol, stored, DTYPES};
pub use device::{
    cooperative_ctxs, cooperative_ctxs_on, ctx, ctx_with, environment, gpu_ctx, private_ctx, quick_ctx, settings,
};
pub use paths::{fixture, repo, scratch};
