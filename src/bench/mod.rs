//! `vkdiff bench …`: speed figures, with the device named and a reference measured in the same run.

mod cpu_reference;
mod kernels;

use anyhow::Result;

#[derive(clap::Subcommand)]
pub enum BenchCommand {
    /// GFLOP/s or GB/s per kernel on SDXL-sized shapes.
    Kernels(kernels::KernelsArgs),
}

pub fn run(cmd: BenchCommand) -> Result<()> {
    match cmd {
        BenchCommand::Kernels(args) => kernels::run(&args),
    }
}
