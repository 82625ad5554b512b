//! Opening a context: the device as its plan says, then the matrix units' trial where the plan
//! asks for one, then tuning where the settings ask for it.

use crate::context::Context;
use crate::device_choice::DeviceChoice;
use crate::error::Result;
use crate::kernel_choice::plan::GemmFamily;
use crate::kernel_choice::trial_run::run_trial;
use crate::settings::Settings;
use std::sync::atomic::Ordering;

impl Context {
    /// Opens the device `choice` names (or the scheduler's, or the best one; see
    /// [`crate::choose`]) to run as `settings` say.
    pub fn new(choice: &DeviceChoice, settings: Settings) -> Result<Context> {
        let ctx = Self::open(choice, settings, false)?;
        ctx.try_matrix_units();
        // After the trial, whose product is timed as it is.
        ctx.set_tuning(settings.tune)?;
        Ok(ctx)
    }

    /// Where this context would run products on the matrix units and its plan tries them first
    /// (`VKDIFF_COOPERATIVE` unset or `auto`), times one on them and on the tiled kernels and keeps the units only where they
    /// agree and are not clearly slower ([`MatrixUnitTrial::keeps_matrix_units`]); says so
    /// where it drops them. A trial that fails drops them too: the tiled kernels then run alone.
    fn try_matrix_units(&self) {
        if self.choices().gemm_family != GemmFamily::Cooperative || !self.shared.plan.trial {
            return;
        }
        let name = &self.info().name;
        match run_trial(self) {
            Ok(trial) => {
                if !trial.keeps_matrix_units() {
                    eprintln!("vkdiff: {}", trial.summary(name));
                    self.choose(|c| c.gemm_family = GemmFamily::Tiled);
                }
                *self.shared.trial.lock().unwrap() = Some(trial);
            }
            Err(e) => {
                eprintln!("vkdiff: `{name}`: the matrix units' trial failed ({e}): using the tiled kernels");
                self.choose(|c| c.gemm_family = GemmFamily::Tiled);
            }
        }
        // The trial's tensors are gone: their buffers go back to the driver, and the peak and the
        // most ever held (which bounds the idle buffers kept) are the caller's work alone.
        crate::memory::release_idle(&self.shared);
        self.shared.most_live.store(self.live_bytes(), Ordering::SeqCst);
        self.reset_peak();
    }
}
