//! `vkdiff bench …`: speed figures, with the device named and a reference measured in the same run
//! (numpy/OpenBLAS, diffusers, torch-fidelity or torch on this machine's CPU, run by one Python
//! runner, `cpu_reference`). The networks are full size with random weights.

mod common;
mod compare;
mod cpu_reference;
mod dataset;
mod fid;
mod gen;
mod kernels;
mod lora;
mod peaks;
mod profile;
mod random_models;
pub mod report;
mod scene;
mod step_rate;
mod unet;
mod vae;
mod workflow;

use anyhow::Result;

#[derive(clap::Subcommand)]
pub enum BenchCommand {
    /// One fixed suite on this device, each figure the median of its runs beside a reference
    /// run the same invocation: the paper's image end to end (and its ablation), SDXL's UNet
    /// and VAE, the headline kernels; a table and, with --out, a JSON for `bench compare`.
    Report(report::ReportArgs),
    /// Reports of one suite side by side: a column per report, a row per figure, speeds
    /// relative to the first; text, Markdown, or an HTML page with charts.
    Compare(compare::CompareArgs),
    /// GFLOP/s or GB/s per kernel on SDXL-sized shapes.
    Kernels(kernels::KernelsArgs),
    /// Frames per second of depth + masks + COCO at 1920×1080, against the paper's Blender.
    Scene(scene::BenchSceneArgs),
    /// Milliseconds per SDXL UNet evaluation (real architecture, random weights) and peak memory,
    /// against diffusers on the CPU.
    Unet(unet::UnetArgs),
    /// Seconds per text-to-image stage (text encoders, UNet steps, VAE) with SDXL base's
    /// architecture and random weights, against diffusers' pipeline on the CPU.
    Gen(gen::GenArgs),
    /// Seconds to merge and restore a rank-r LoRA over SDXL base's UNet (random weights) on the
    /// device, against the same merge in torch on the CPU.
    Lora(lora::LoraArgs),
    /// Seconds per step of the paper's workflow (SDXL + depth ControlNet + IP-Adapter + two
    /// merged LoRAs, random full-size weights) against a plain step measured in the same run.
    Workflow(workflow::WorkflowArgs),
    /// Seconds per image of `vkdiff dataset` with the paper's workflow (random full-size
    /// weights) by stage, against one `vkdiff gen` per image measured in the same run.
    Dataset(dataset::DatasetArgs),
    /// Seconds and activation memory of SDXL's VAE decode (random weights), whole and in
    /// diffusers' tiles, beside the memory plan's estimates.
    Vae(vae::VaeArgs),
    /// Images per second of FID features (torch-fidelity's InceptionV3, random weights) over a
    /// folder of PNGs, against torch-fidelity on the CPU.
    Fid(fid::FidArgs),
}

/// Runs `cmd`; `env` is the process's environment as the command line read it, the one place.
pub fn run(cmd: BenchCommand, env: &vkdiff_runtime::Environment) -> Result<()> {
    match cmd {
        BenchCommand::Report(args) => report::run(&args, env),
        BenchCommand::Compare(args) => compare::run(&args),
        BenchCommand::Kernels(args) => kernels::run(&args, env),
        BenchCommand::Scene(args) => scene::run(&args),
        BenchCommand::Unet(args) => unet::run(&args, env),
        BenchCommand::Gen(args) => gen::run(&args, env),
        BenchCommand::Lora(args) => lora::run(&args, env),
        BenchCommand::Workflow(args) => workflow::run(&args, env),
        BenchCommand::Dataset(args) => dataset::run(&args, env),
        BenchCommand::Fid(args) => fid::run(&args, env),
        BenchCommand::Vae(args) => vae::run(&args, env),
    }
}
