//! `vkdiff bench …`: speed figures, with the device named and a reference measured in the same run.

mod cpu_reference;
mod gen;
mod kernels;
mod unet;

use anyhow::Result;

#[derive(clap::Subcommand)]
pub enum BenchCommand {
    /// GFLOP/s or GB/s per kernel on SDXL-sized shapes.
    Kernels(kernels::KernelsArgs),
    /// Frames per second of depth + masks + COCO at 1920×1080, against the paper's Blender.
    Scene(crate::scene_cmd::BenchSceneArgs),
    /// Milliseconds per SDXL UNet evaluation (real architecture, random weights) and peak memory,
    /// against diffusers on the CPU.
    Unet(unet::UnetArgs),
    /// Seconds per text-to-image stage (text encoders, UNet steps, VAE) with SDXL base's
    /// architecture and random weights, against diffusers' pipeline on the CPU.
    Gen(gen::GenArgs),
}

pub fn run(cmd: BenchCommand) -> Result<()> {
    match cmd {
        BenchCommand::Kernels(args) => kernels::run(&args),
        BenchCommand::Scene(args) => crate::scene_cmd::run_bench_scene(args),
        BenchCommand::Unet(args) => unet::run(&args),
        BenchCommand::Gen(args) => gen::run(&args),
    }
}
