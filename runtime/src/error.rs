use crate::settings::DEFAULT_SUBMIT_GFLOP;
use ash::vk;
use vkdiff_setting::Message;

/// Everything the runtime can fail with; each message is one line a user can act on.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(
        "no Vulkan loader found ({0}); install libvulkan1 and a driver (mesa-vulkan-drivers gives the CPU device \
        lavapipe)"
    )]
    NoLoader(String),
    #[error("no Vulkan device found; install a driver (mesa-vulkan-drivers gives the CPU device lavapipe)")]
    NoDevice,
    #[error(
        "no Vulkan driver found ({0}); install your GPU's Vulkan driver, or mesa-vulkan-drivers for the CPU device \
        lavapipe"
    )]
    NoDriver(String),
    #[error("device {index} requested ({requested_by}) but only {count} Vulkan device(s) exist; see `vkdiff devices`")]
    BadDeviceIndex { index: usize, count: usize, requested_by: Message },
    #[error("{0}")]
    BadDeviceSpec(String),
    #[error("{requested_by} names device {spec}, but {why}; see `vkdiff devices`")]
    NoSuchDevice { spec: String, why: &'static str, requested_by: Message },
    #[error("{0}")]
    NotVisible(String),
    #[error("a GPU is required (--require-gpu or VKDIFF_REQUIRE_GPU=1), but {0}")]
    NoGpu(String),
    #[error("device `{device}` cannot run vkdiff: {reason}")]
    Unsupported { device: String, reason: String },
    #[error("Vulkan call {call} failed: {result}")]
    Vulkan { call: &'static str, result: vk::Result },
    #[error(
        "the Vulkan device was lost in {0}: the driver reset the GPU, most often because one submission ran past \
        the system's GPU watchdog (Windows TDR: 2 s; Linux amdgpu: lockup_timeout) or the driver crashed; \
        VKDIFF_SUBMIT_GFLOP below its default of {DEFAULT_SUBMIT_GFLOP} makes each submission shorter"
    )]
    DeviceLost(&'static str),
    #[error(
        "a submission to the device did not finish in {seconds} s: the device hangs, or runs far slower than \
        expected (VKDIFF_SUBMIT_TIMEOUT=SECONDS waits longer)"
    )]
    SubmitTimeout { seconds: f64 },
    #[error("{0}")]
    BadSetting(String),
    /// A `VKDIFF_*` variable's value that its setting does not take.
    #[error(transparent)]
    BadVariable(vkdiff_setting::BadVariable),
    #[error("device memory: {0}")]
    Memory(String),
    #[error("VKDIFF_VALIDATE=1 needs the Khronos validation layer (Debian: apt-get install vulkan-validationlayers)")]
    NoValidationLayer,
    #[error("{0}")]
    Shape(String),
    #[error("kernel `{kernel}` has no compiled variant with {want}")]
    NoVariant { kernel: &'static str, want: String },
}

pub type Result<T> = std::result::Result<T, Error>;

/// Wraps an `ash` result with the name of the call that produced it.
pub(crate) trait VkContext<T> {
    fn vk(self, call: &'static str) -> Result<T>;
}

impl<T> VkContext<T> for std::result::Result<T, vk::Result> {
    fn vk(self, call: &'static str) -> Result<T> {
        self.map_err(|result| match result {
            vk::Result::ERROR_DEVICE_LOST => Error::DeviceLost(call),
            result => Error::Vulkan { call, result },
        })
    }
}

/// Fails with a shape error unless `cond` holds.
pub(crate) fn ensure(cond: bool, message: impl FnOnce() -> String) -> Result<()> {
    if cond {
        Ok(())
    } else {
        Err(Error::Shape(message()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_lost_device_names_the_likely_cause_and_the_setting() {
        let lost: std::result::Result<(), vk::Result> = Err(vk::Result::ERROR_DEVICE_LOST);
        let text = lost.vk("vkWaitForFences").unwrap_err().to_string();
        assert!(text.starts_with("the Vulkan device was lost in vkWaitForFences"), "{text}");
        assert!(text.contains("TDR") && text.contains("VKDIFF_SUBMIT_GFLOP below its default of 100"), "{text}");
        let other: std::result::Result<(), vk::Result> = Err(vk::Result::ERROR_OUT_OF_DEVICE_MEMORY);
        assert!(matches!(other.vk("vkQueueSubmit"), Err(Error::Vulkan { .. })));
    }
}
