//! Which Vulkan device a command runs on.

use vkdiff_runtime::{DeviceChoice, DeviceSpec};

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
    pub fn choice(&self) -> DeviceChoice {
        DeviceChoice { device: self.device.clone(), require_gpu: self.require_gpu }
    }
}
