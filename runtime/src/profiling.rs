//! Timing a context's dispatches: every recording, or every recording one call makes.

use crate::context::Context;
use crate::timing::Timing;
use std::sync::atomic::Ordering;

impl Context {
    /// Makes every recording started from now on time its dispatches, so a network's
    /// recording can be profiled without threading a flag through its layers.
    pub fn set_profiling(&self, on: bool) {
        self.shared.profiling.store(on, Ordering::SeqCst);
    }

    pub(crate) fn profiling(&self) -> bool {
        self.shared.profiling.load(Ordering::SeqCst)
    }

    /// Runs `f` with every recording it makes timing its dispatches, and returns what `f` returns
    /// with the device time of each dispatch its runs made, in order: a whole network call
    /// (a VAE decode, tiles and all) profiled without a handle on its recordings.
    pub fn profiled<T>(&self, f: impl FnOnce() -> T) -> (T, Vec<Timing>) {
        *self.shared.collected.lock().unwrap() = Some(Vec::new());
        self.set_profiling(true);
        let out = f();
        self.set_profiling(false);
        (out, self.shared.collected.lock().unwrap().take().unwrap_or_default())
    }
}
