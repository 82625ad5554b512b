//! The kernel variants recorded on this thread while a closure runs: what tests assert the
//! kernel choice by where the recordings are made deep inside a network or a pipeline.

use std::cell::RefCell;
use vkdiff_kernels::Variant;

thread_local! {
    static LISTED: RefCell<Option<Vec<&'static Variant>>> = const { RefCell::new(None) };
}

/// Runs `f`, returning with its result the variants of every recording finished on this
/// thread meanwhile, each once, in the order first recorded.
pub fn listing_variants<R>(f: impl FnOnce() -> R) -> (R, Vec<&'static Variant>) {
    let outer = LISTED.with(|l| l.borrow_mut().replace(Vec::new()));
    let result = f();
    let listed = LISTED.with(|l| std::mem::replace(&mut *l.borrow_mut(), outer)).unwrap_or_default();
    note(listed.iter().copied()); // an enclosing listing sees them too
    (result, listed)
}

/// Adds a finished recording's variants to the listing, where one is being made.
pub(crate) fn note(variants: impl Iterator<Item = &'static Variant>) {
    LISTED.with(|l| {
        if let Some(listed) = l.borrow_mut().as_mut() {
            for v in variants {
                if !listed.iter().any(|seen| std::ptr::eq(*seen, v)) {
                    listed.push(v);
                }
            }
        }
    });
}
