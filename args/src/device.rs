//! Which Vulkan device a command runs on.

use vkdiff_runtime::{Context, DeviceChoice, DeviceSpec, Environment, Settings};

/// `--device` and `--require-gpu`, shared by every command that opens a device.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct DeviceArgs {
    /// Vulkan device: its index, UUID or PCI address, as `vkdiff devices` prints them [default:
    /// $VKDIFF_DEVICE, else the GPU CUDA_VISIBLE_DEVICES, ROCR_VISIBLE_DEVICES or SLURM_LOCALID
    /// give this process, else the first discrete GPU, integrated GPU, then the CPU].
    #[arg(long, value_name = "INDEX|UUID|PCI")]
    pub device: Option<DeviceSpec>,
    /// Refuse to run on a CPU device (lavapipe), naming the Vulkan drivers found [also
    /// VKDIFF_REQUIRE_GPU=1].
    #[arg(long)]
    pub require_gpu: bool,
}

impl DeviceArgs {
    /// The device these flags choose, else `env`'s `VKDIFF_DEVICE`, with its scheduler's variables.
    pub fn choice(&self, env: &Environment) -> vkdiff_runtime::Result<DeviceChoice> {
        DeviceChoice::from_environment(self.device.clone(), self.require_gpu, env)
    }

    /// Opens the device these flags and `env` choose, run as its `VKDIFF_*` settings say.
    pub fn open(&self, env: &Environment) -> vkdiff_runtime::Result<Context> {
        Context::new(&self.choice(env)?, Settings::from_environment(env)?)
    }
}
