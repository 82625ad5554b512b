//! `vkdiff`: command-line parsing and nothing else; every subcommand lives in its own module.

mod bench;
mod dataset_cmd;
mod devices_cmd;
mod eval_cmd;
mod fid_cmd;
mod gen_cmd;
mod model_args;
mod progress;
mod scene_cmd;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "vkdiff",
    version,
    about = "Procedural scenes to photorealistic, exactly annotated training images, on any Vulkan GPU"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render procedural mushroom beds: metric depth (EXR), instance masks, COCO, control images.
    Scene(scene_cmd::SceneArgs),
    /// Text-to-image with an SDXL model: prompt in, PNG (with its settings) out.
    Gen(Box<gen_cmd::GenArgs>),
    /// Scenes made into photoreal, exactly annotated training images: sharded, resumable.
    Dataset(Box<dataset_cmd::DatasetArgs>),
    /// List every Vulkan device and what vkdiff would use on it.
    Devices(devices_cmd::DevicesArgs),
    /// Score COCO predictions against COCO ground truth: AP/AR as pycocotools, F1, mIoU.
    Eval(eval_cmd::EvalArgs),
    /// FID and KID between real photos and generated images, as torch-fidelity computes them,
    /// with its InceptionV3 on the Vulkan device.
    Fid(fid_cmd::FidArgs),
    /// Measure speed: kernels, networks, scene generation.
    #[command(subcommand)]
    Bench(bench::BenchCommand),
}

fn main() {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Scene(args) => scene_cmd::run_scene(args),
        Command::Gen(args) => gen_cmd::run(&args),
        Command::Dataset(args) => dataset_cmd::run(&args),
        Command::Devices(args) => devices_cmd::run(&args),
        Command::Eval(args) => eval_cmd::run(&args),
        Command::Fid(args) => fid_cmd::run(&args),
        Command::Bench(cmd) => bench::run(cmd),
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
