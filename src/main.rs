//! `vkdiff`: command-line parsing and nothing else; every subcommand lives in its own module.

mod scene_cmd;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "vkdiff", version, about = "Procedural scenes to photorealistic, exactly annotated training images")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    Scene(scene_cmd::SceneArgs),
    /// Measure speed.
    #[command(subcommand)]
    Bench(BenchCommand),
}

#[derive(Subcommand)]
enum BenchCommand {
    Scene(scene_cmd::BenchSceneArgs),
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Scene(args) => scene_cmd::run_scene(args),
        Command::Bench(BenchCommand::Scene(args)) => scene_cmd::run_bench_scene(args),
    }
}
