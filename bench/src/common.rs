//! What the benchmarks share: the flags of those measured against a CPU reference, and how a
//! result row is printed (a JSON line, or one table line).

use anyhow::Result;

/// The flags of every benchmark that runs a CPU reference.
#[derive(clap::Args)]
pub struct Common {
    #[command(flatten)]
    pub device: vkdiff_args::DeviceArgs,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Skip the CPU reference (numpy, diffusers, torch-fidelity or torch, run with
    /// $VKDIFF_REFERENCE_PYTHON, else python3).
    #[arg(long)]
    pub no_cpu_reference: bool,
}

impl Common {
    /// `row` as a JSON line with `--json`, else `table(row)`.
    pub fn print<R: serde::Serialize>(&self, row: &R, table: impl FnOnce(&R) -> String) -> Result<()> {
        if self.json {
            println!("{}", serde_json::to_string(row)?);
        } else {
            println!("{}", table(row));
        }
        Ok(())
    }
}
