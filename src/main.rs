//! `vkdiff`: the command line. Each command parses its flags, calls its one library entry, and
//! prints; the benchmarks live in `vkdiff-bench`, the shared flags in `vkdiff-args`.

mod dataset_audit_cmd;
mod dataset_cmd;
mod dataset_export_cmd;
mod dataset_preview_cmd;
mod dataset_stats_cmd;
mod devices_cmd;
mod devices_compile;
mod eval_cmd;
mod exit_code;
mod fid_cmd;
mod gen_cmd;
mod help;
mod scene_cmd;

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "vkdiff",
    version = env!("VKDIFF_VERSION"),
    after_help = help::top(),
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
    #[command(after_help = help::gen())]
    Gen(Box<gen_cmd::GenArgs>),
    /// Scenes made into photoreal, exactly annotated training images: sharded, resumable.
    #[command(after_help = help::dataset())]
    Dataset(Box<dataset_cmd::DatasetArgs>),
    /// List every Vulkan device and what vkdiff would use on it.
    Devices(devices_cmd::DevicesArgs),
    /// Score COCO predictions against COCO ground truth: AP/AR as pycocotools, F1, mIoU.
    #[command(after_help = help::eval())]
    Eval(eval_cmd::EvalArgs),
    /// FID and KID between real photos and generated images, as torch-fidelity computes them,
    /// with its InceptionV3 on the Vulkan device.
    #[command(after_help = help::fid())]
    Fid(fid_cmd::FidArgs),
    /// Measure speed: kernels, networks, scene generation.
    #[command(subcommand, after_help = help::bench())]
    Bench(vkdiff_bench::BenchCommand),
}

fn main() {
    // Output piped into `head` or `grep -q` ends quietly when the reader goes, as a shell
    // command does, not with a panic.
    // SAFETY: restoring a signal's default action before any thread starts.
    unsafe { libc::signal(libc::SIGPIPE, libc::SIG_DFL) };
    vkdiff_setting::install_version(env!("VKDIFF_VERSION"));
    let cli = parse();
    // The libraries name settings as data; errors here name them by this command's flags.
    let names = if matches!(cli.command, Command::Dataset(_)) { vkdiff_args::dataset_flag } else { vkdiff_args::flag };
    vkdiff_setting::name_settings_with(names);
    // The one read of the process's environment: every command is handed this value.
    let env = vkdiff_runtime::Environment::of_process();
    let result = check_environment(&env).map_err(anyhow::Error::from).and_then(|()| match cli.command {
        Command::Scene(args) => scene_cmd::run_scene(args),
        Command::Gen(args) => gen_cmd::run(&args, &env),
        Command::Dataset(args) => dataset_cmd::run(&args, &env),
        Command::Devices(args) => devices_cmd::run(&args, &env),
        Command::Eval(args) => eval_cmd::run(&args),
        Command::Fid(args) => fid_cmd::run(&args, &env),
        Command::Bench(cmd) => vkdiff_bench::run(cmd, &env),
    });
    if let Err(e) = result {
        eprintln!("error: {}", one_line(&e));
        let code = exit_code::of(&e);
        if vkdiff_runtime::device_hung() {
            use std::io::Write;
            let _ = std::io::stdout().flush();
            // SAFETY: ends the process at once; the timed-out work's threads end with it.
            unsafe { libc::_exit(code) };
        }
        std::process::exit(code);
    }
}

/// Every `VKDIFF_*` setting checked before any work, whether or not the command opens a device:
/// a value one does not take ends the run as any refusal does.
fn check_environment(env: &vkdiff_runtime::Environment) -> vkdiff_runtime::Result<()> {
    vkdiff_runtime::Settings::from_environment(env)?;
    vkdiff_runtime::DeviceChoice::from_environment(None, false, env).map(drop)
}

/// The command line; `dataset --render-only` needs no `--model`, which every other generating
/// command needs.
fn parse() -> Cli {
    let command = Cli::command().mut_subcommand("dataset", |c| {
        c.mut_arg("model", |a| a.required(false).required_unless_present("render_only"))
    });
    Cli::from_arg_matches(&command.get_matches()).unwrap_or_else(|e| e.exit())
}

/// Opens the Vulkan device `args` choose and has it say when lavapipe compiles kernels, which on
/// a cold shader cache can take minutes before the first image. A CPU device taken for want of
/// a GPU says so, with the drivers the loader found.
fn open_device(
    args: &vkdiff_args::DeviceArgs,
    env: &vkdiff_runtime::Environment,
) -> vkdiff_runtime::Result<vkdiff_runtime::Context> {
    let choice = args.choice(env)?;
    let ctx = vkdiff_runtime::Context::new(&choice, vkdiff_runtime::Settings::from_environment(env)?)?;
    let info = ctx.info();
    if info.kind == vkdiff_runtime::DeviceKind::Cpu && choice.device.is_none() {
        let icds = vkdiff_runtime::loader_icds(env).join(", ");
        eprintln!(
            "device: {} — the CPU, no GPU's Vulkan driver was found (driver manifests: {icds}); --require-gpu \
            refuses to run so",
            info.name
        );
    } else {
        eprintln!("device: {}", info.name);
    }
    ctx.on_compile(std::sync::Arc::new(|kernels| {
        // On a terminal, the line clears a progress bar, which redraws below it.
        let clear = if std::io::IsTerminal::is_terminal(&std::io::stderr()) { "\r\x1b[K" } else { "" };
        let plural = if kernels == 1 { "" } else { "s" };
        eprintln!("{clear}compiling {kernels} kernel{plural} for this driver, once (Mesa's shader cache keeps them)");
    }));
    Ok(ctx)
}

/// The error and its causes joined by `: `, each said once: an error that already ends with its
/// cause's text (a file error naming the path and the OS's reason) does not repeat it.
fn one_line(error: &anyhow::Error) -> String {
    let mut line = String::new();
    for cause in error.chain() {
        let text = cause.to_string();
        if line.ends_with(&text) {
            continue;
        }
        if !line.is_empty() {
            line.push_str(": ");
        }
        line.push_str(&text);
    }
    line
}

#[cfg(test)]
mod tests {
    use clap::CommandFactory;

    /// Every flag and positional of every command, `bench` and `dataset`'s subcommands
    /// included, says what it is; the commands users start from show examples.
    #[test]
    fn every_argument_has_help_and_the_main_commands_have_examples() {
        fn walk(command: &clap::Command, path: &str, missing: &mut Vec<String>) {
            for arg in command.get_arguments().filter(|a| !["help", "version"].contains(&a.get_id().as_str())) {
                if arg.get_help().is_none_or(|h| h.to_string().trim().is_empty()) {
                    missing.push(format!("{path} {}", arg.get_id()));
                }
            }
            for sub in command.get_subcommands() {
                walk(sub, &format!("{path} {}", sub.get_name()), missing);
            }
        }
        let cli = super::Cli::command();
        let mut missing = Vec::new();
        walk(&cli, "vkdiff", &mut missing);
        assert!(missing.is_empty(), "arguments without help: {missing:?}");
        for name in ["gen", "dataset", "eval", "fid", "bench"] {
            let sub = cli.find_subcommand(name).unwrap();
            let after = sub.get_after_help().map(|h| h.to_string()).unwrap_or_default();
            assert!(after.contains("Examples") && after.contains("Exit codes"), "{name}: {after}");
        }
    }
}
