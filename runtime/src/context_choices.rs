//! A context's choices, read and changed, and what they started from.

use crate::choices::Choices;
use crate::context::Context;
use crate::kernel_choice::plan::KernelPlan;
use crate::settings::Settings;

impl Context {
    pub fn choices(&self) -> Choices {
        *self.shared.choices.lock().unwrap()
    }

    /// Changes this context's choices for recordings made from now on; limits above the
    /// device's are lowered to them.
    /// `change` runs on a copy, outside the lock, so it may read the context (its choices too).
    pub fn choose(&self, change: impl FnOnce(&mut Choices)) {
        let mut choices = self.choices();
        change(&mut choices);
        *self.shared.choices.lock().unwrap() = choices.within(&self.shared.info);
    }

    /// Turns the GPU paths on or off for this context (tests run both on one device), with the
    /// kernels the device's plan takes on them: the GEMM family a GPU would take (the matrix
    /// units where they fit, else tiled) and, as on a GPU, the kernels that run fastest whatever
    /// their compile time.
    pub fn set_gpu_paths(&self, on: bool) {
        let plan = KernelPlan::for_device(&self.shared.info, &Settings { gpu_paths: on, ..self.shared.settings });
        self.choose(|c| {
            c.gpu_paths = on;
            if on {
                c.gemm_family = plan.gemm;
                c.quick_compile = plan.quick_compile;
            }
        });
    }

    /// The settings this context was opened with.
    pub fn settings(&self) -> Settings {
        self.shared.settings
    }

    /// The kernels this context started with, and why.
    pub fn plan(&self) -> &KernelPlan {
        &self.shared.plan
    }
}
