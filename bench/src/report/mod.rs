//! `vkdiff bench report`: one fixed suite on the chosen device, each figure the median of its
//! runs after a warm-up, with its spread, peak memory and first run, beside a reference measured
//! in the same invocation; a table on the terminal and a JSON that `bench compare` lines up with
//! other machines' (llama-bench's rows, MLPerf's fixed work and medians, the system described).

mod figure;
mod image;
mod networks;
mod peer;
mod references;
mod system;
mod table;

pub use figure::{show, Figure, Reference, Runs};
pub use system::System;

use anyhow::Result;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;
use vkdiff_pipeline::LoraSetting;
use vkdiff_runtime::{Context, Dtype, Environment};

/// Changes whenever a figure's work changes: reports of other versions do not compare.
pub const SUITE_VERSION: u32 = 1;

#[derive(Clone, Copy, PartialEq, Eq, Debug, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Group {
    /// The paper's image end to end.
    Image,
    /// The paper's Table 4: the image without each of its parts (in the full suite only,
    /// unless named).
    Ablation,
    /// SDXL's UNet, one evaluation.
    Unet,
    /// SDXL's VAE, one decode.
    Vae,
    /// The headline products: a linear layer, a convolution, attention.
    Kernels,
    /// stable-diffusion.cpp's Vulkan build beside vkdiff, SDXL text-to-image from one single
    /// file on the same device (in the full suite only, unless named).
    Peer,
}

/// Where the reference runs.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ReferenceChoice {
    /// diffusers (and numpy) in float32 on this machine's CPU.
    Cpu,
    /// diffusers on the CUDA GPU, at the figure's precision.
    Cuda,
    /// None: vkdiff's figures only.
    None,
}

#[derive(clap::Args)]
pub struct ReportArgs {
    #[command(flatten)]
    device: vkdiff_args::DeviceArgs,
    /// The small suite: 512² images with 2 of their 30 steps timed (the rest counted at the
    /// median of the timed steps after the first), the UNet and VAE at 512² in f16, one timed run
    /// of each, no warm-up image on either side; for CPU devices and a first look. Reports of the
    /// two suites do not compare.
    #[arg(long)]
    quick: bool,
    /// Where the reference beside each figure runs (diffusers for the networks, numpy for the
    /// linear layer), with $VKDIFF_REFERENCE_PYTHON, else python3.
    #[arg(long, value_enum, default_value = "cpu")]
    reference_device: ReferenceChoice,
    /// Also write the report as JSON here (for `bench compare`).
    #[arg(long, value_name = "FILE.json")]
    out: Option<PathBuf>,
    /// Image side in pixels for the image, UNet and VAE figures, in place of the suite's (1024;
    /// 512 with --quick): a multiple of 64. Reports of other sizes do not compare.
    #[arg(long, value_name = "PIXELS")]
    size: Option<usize>,
    /// Timed runs of each figure after its warm-up [default: 3; 1 with --quick; the kernels'
    /// rows 10 in both suites, half a second each].
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    runs: Option<u32>,
    /// Only these groups (comma-separated): image, ablation, unet, vae, kernels, peer [default:
    /// all, the ablation and the peer in the full suite only].
    #[arg(long, value_enum, value_delimiter = ',')]
    only: Vec<Group>,
    /// Time these models instead of random weights of SDXL base's architecture: an SDXL model
    /// (folder, single file or Hugging Face id), with the guides below where given.
    #[arg(long, value_name = "DIR|FILE|ID")]
    model: Option<PathBuf>,
    /// A depth ControlNet for --model.
    #[arg(long, requires = "model", value_name = "DIR|FILE|ID")]
    controlnet: Option<PathBuf>,
    /// A UNet in --model's place for the image rows (a distilled UNet such as SDXL-Lightning's:
    /// the same architecture, so the UNet rows time the model's own).
    #[arg(long, requires = "model", value_name = "DIR|FILE|ID")]
    unet: Option<PathBuf>,
    /// An IP-Adapter for --model (with --image-encoder).
    #[arg(long, requires_all = ["model", "image_encoder"], value_name = "FILE|ID")]
    ip_adapter: Option<PathBuf>,
    /// The IP-Adapter's image encoder.
    #[arg(long, requires = "ip_adapter", value_name = "DIR|ID")]
    image_encoder: Option<PathBuf>,
    /// Seconds stable-diffusion.cpp (the peer) may take to load its file and run its steps
    /// before it is stopped and the report says so.
    #[arg(long, default_value_t = 600, value_name = "SECONDS")]
    peer_timeout: u64,
    /// A LoRA for --model, FILE[:STRENGTH]; repeat it for several (the ablation's L1 and L2
    /// are the first two).
    #[arg(long, requires = "model", value_parser = vkdiff_args::parse_lora, value_name = "FILE[:STRENGTH]")]
    lora: Vec<LoraSetting>,
}

/// The models a user gave, resolved.
pub struct UserModels {
    pub model: PathBuf,
    pub unet: Option<PathBuf>,
    pub controlnet: Option<PathBuf>,
    pub ip_adapter: Option<PathBuf>,
    pub image_encoder: Option<PathBuf>,
    pub loras: Vec<LoraSetting>,
}

/// The work of the chosen suite.
pub struct Plan {
    pub quick: bool,
    pub dtype: Dtype,
    pub image_size: usize,
    /// Steps of the paper's image, and how many of them are timed.
    pub steps: usize,
    pub steps_timed: usize,
    pub network_size: usize,
    pub runs: usize,
    /// Timed runs of each kernel row, on both sides: one run is about half a second of
    /// repetitions, so ten cost little and give a median and a spread where one would give a
    /// single sample of a shared machine's noise.
    pub kernel_runs: usize,
    /// Whether each figure runs once untimed first, and the paper's image's reference with it
    /// (the quick suite warms up neither side: on CPU devices vkdiff's kernels compile as they
    /// are recorded, which the set's setup holds, not as they first run).
    pub warm_up: bool,
    pub reference: ReferenceChoice,
    pub peer_timeout: std::time::Duration,
}

impl Plan {
    fn of(args: &ReportArgs) -> Plan {
        let quick = args.quick;
        let size = args.size.unwrap_or(if quick { 512 } else { 1024 });
        Plan {
            quick,
            dtype: Dtype::F16,
            image_size: size,
            steps: 30,
            steps_timed: if quick { 2 } else { 30 },
            network_size: size,
            runs: args.runs.map_or(if quick { 1 } else { 3 }, |r| r as usize),
            kernel_runs: args.runs.map_or(10, |r| r as usize),
            warm_up: !quick,
            reference: args.reference_device,
            peer_timeout: std::time::Duration::from_secs(args.peer_timeout),
        }
    }

    fn suite(&self, args: &ReportArgs) -> String {
        let quick = if self.quick { " --quick" } else { "" };
        let size = args.size.map_or(String::new(), |s| format!(" --size {s}"));
        format!("vkdiff bench report/{SUITE_VERSION}{quick}{size}")
    }
}

/// A whole report: the suite, the machine, what ran, the figures.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Report {
    pub suite: String,
    pub suite_version: u32,
    pub system: System,
    /// The weights timed: random (the real architectures) or the user's.
    pub models: String,
    pub figures: Vec<Figure>,
}

fn wants(args: &ReportArgs, group: Group) -> bool {
    if args.only.is_empty() {
        !matches!(group, Group::Ablation | Group::Peer) || !args.quick
    } else {
        args.only.contains(&group)
    }
}

pub fn run(args: &ReportArgs, env: &Environment) -> Result<()> {
    if let Some(out) = &args.out {
        let parent = out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(std::path::Path::new("."));
        vkdiff_args::ensure_usage(parent.is_dir(), || {
            format!("--out {}: no such folder {}", out.display(), parent.display())
        })?;
    }
    if let Some(size) = args.size {
        vkdiff_args::ensure_usage(size >= 64 && size.is_multiple_of(64), || {
            format!("--size {size} must be a multiple of 64, at least 64")
        })?;
    }
    let user = resolve_user(args, env)?;
    let plan = Plan::of(args);
    let ctx = args.device.open(env)?;
    let system = System::of(&ctx, env);
    eprintln!("report: {} on {} ({})", plan.suite(args), system.device, system.driver);
    let mut jobs: Vec<(Figure, networks::Job)> = Vec::new();
    if wants(args, Group::Image) || wants(args, Group::Ablation) {
        jobs.extend(image_jobs(args, &plan, &ctx, user.as_ref())?);
    }
    let model = user.as_ref().map(|u| u.model.as_path());
    if wants(args, Group::Unet) {
        jobs.extend(networks::unet(&ctx, &plan, model)?);
    }
    if wants(args, Group::Vae) {
        jobs.extend(networks::vae(&ctx, &plan, model)?);
    }
    if wants(args, Group::Kernels) {
        jobs.extend(networks::kernels(&ctx, &plan)?);
    }
    if wants(args, Group::Peer) {
        // Writing 7 GB can fail where the rest ran (a small temporary folder): the other
        // figures stand.
        match peer::peer(&ctx, &plan, model) {
            Ok(job) => jobs.push(job),
            Err(e) => eprintln!("report: the peer is left out: {e:#}"),
        }
    }
    drop(ctx);
    let models = match &user {
        Some(u) => format!("{}", u.model.display()),
        None => "random weights of SDXL base, its depth ControlNet, a ViT-H IP-Adapter and two rank-32 LoRAs".into(),
    };
    let mut report = Report { suite: plan.suite(args), suite_version: SUITE_VERSION, system, models, figures: vec![] };
    // vkdiff's own figures first, in case the references do not finish (a lent GPU's minutes).
    report.figures = jobs.iter().map(|(f, _)| f.clone()).collect();
    write(args, &report)?;
    report.figures = references::references(&plan, jobs, env);
    print!("{}", table::markdown(&report));
    write(args, &report)?;
    if let Some(out) = &args.out {
        eprintln!("report: written to {}", out.display());
    }
    Ok(())
}

/// The models `--model` and its guides name, resolved (Hugging Face ids to their files).
fn resolve_user(args: &ReportArgs, env: &Environment) -> Result<Option<UserModels>> {
    use vkdiff_args::Wants;
    let Some(model) = &args.model else { return Ok(None) };
    let resolve = |flag: &str, p: &PathBuf, wants| vkdiff_args::resolve_model(flag, p, wants, env);
    let optional = |flag: &str, p: &Option<PathBuf>, wants| p.as_ref().map(|p| resolve(flag, p, wants)).transpose();
    Ok(Some(UserModels {
        model: resolve("--model", model, Wants::Either)?,
        unet: optional("--unet", &args.unet, Wants::Either)?,
        controlnet: optional("--controlnet", &args.controlnet, Wants::Either)?,
        ip_adapter: optional("--ip-adapter", &args.ip_adapter, Wants::File)?,
        image_encoder: optional("--image-encoder", &args.image_encoder, Wants::Folder)?,
        loras: args
            .lora
            .iter()
            .map(|l| Ok(LoraSetting { path: resolve("--lora", &l.path, Wants::File)?, ..l.clone() }))
            .collect::<Result<_>>()?,
    }))
}

/// The paper's image and its ablation, each with the reference it waits for: diffusers' own
/// pipeline beside the whole workflow.
fn image_jobs(
    args: &ReportArgs,
    plan: &Plan,
    ctx: &Context,
    user: Option<&UserModels>,
) -> Result<Vec<(Figure, networks::Job)>> {
    let settings = user.map(|u| image::user_settings(plan, u));
    let mut workflow = image::Workflow::load(ctx, plan, settings.as_ref())?;
    let mut images = Vec::new();
    if wants(args, Group::Image) {
        eprintln!("report: the paper's image");
        let paper = image::paper_image(&mut workflow, plan, ctx)?;
        eprintln!("report: the paper's image at 4 steps (Lightning's recipe)");
        let few = image::few_step_image(&mut workflow, plan, ctx)?;
        images.extend([paper, few]);
    }
    if wants(args, Group::Ablation) {
        images.extend(image::ablation(&mut workflow, plan, ctx)?);
    }
    let ip_adapter = workflow.models.style.is_some();
    let configs =
        networks::workflow_configs(user.map(|u| u.model.as_path()), user.map(|u| u.controlnet.as_deref()), ip_adapter);
    let thirty = images.iter().find(|f| f.id == "image").map(|f| f.runs.median);
    Ok(images
        .into_iter()
        .map(|figure| {
            let job = match (&configs, thirty) {
                (_, Some(thirty)) if figure.id == image::FEW_STEP_ID => networks::Job::Measured(Reference::Measured {
                    value: thirty,
                    what: format!("the paper's {}-step image, this run", plan.steps),
                }),
                (Some(configs), _) if figure.id == "image" => networks::Job::Workflow {
                    configs: configs.clone(),
                    size: plan.image_size,
                    steps_timed: plan.steps_timed,
                    steps: plan.steps,
                    dtype: plan.dtype,
                    warm_up: plan.warm_up,
                },
                (Some(_), _) => networks::Job::None("diffusers' pipeline runs beside the whole workflow only".into()),
                (None, _) => {
                    networks::Job::None("diffusers' pipeline needs diffusers folders (with a ControlNet)".into())
                }
            };
            (figure, job)
        })
        .collect())
}

fn write(args: &ReportArgs, report: &Report) -> Result<()> {
    if let Some(out) = &args.out {
        vkdiff_formats::atomic::write_atomic(out, &serde_json::to_vec_pretty(report)?)?;
    }
    Ok(())
}
