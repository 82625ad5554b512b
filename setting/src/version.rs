//! The version every file vkdiff writes records (PNG text, `dataset.json`, the FID feature
//! cache, scene metadata): the crate version plus the commit it was built from, which the
//! program installs once at start ([`install_version`]); a library used on its own reports the
//! crate version alone.

use std::sync::OnceLock;

static VERSION: OnceLock<&'static str> = OnceLock::new();

/// Makes `version` the one every file records from now on (the first call wins).
pub fn install_version(version: &'static str) -> bool {
    VERSION.set(version).is_ok()
}

/// The version this process records.
pub fn version() -> &'static str {
    VERSION.get().copied().unwrap_or(env!("CARGO_PKG_VERSION"))
}
