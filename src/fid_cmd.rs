//! `vkdiff fid`: FID and KID between a folder of real photos and a folder of generated images, as
//! torch-fidelity computes them (`fidelity --fid --kid --input1 FAKE --input2 REAL`), with its
//! InceptionV3 running on the Vulkan device.

use anyhow::Result;
use std::path::{Path, PathBuf};
use vkdiff_args::Precision;
use vkdiff_args::Progress;
use vkdiff_eval::fid::{user_cache_base, CacheDir, FidJob, FidRequest, FolderFeatures};

#[derive(clap::Args)]
pub struct FidArgs {
    /// The real photos (png, jpg, jpeg; not recursive).
    real: PathBuf,
    /// The generated images, or a `vkdiff dataset` folder (its images/).
    fake: PathBuf,
    /// torch-fidelity's InceptionV3 weights, `weights-inception-2015-12-05-6726825d.pth` as torch
    /// saved it, or the same tensors as .safetensors; a path or a Hugging Face id.
    #[arg(long, value_name = "FILE|ID")]
    inception: PathBuf,
    /// Keep each folder's features (by file, size and time) and reuse them: the real set is
    /// encoded once for every comparison against it.
    #[arg(long)]
    cache: bool,
    /// Where `--cache` keeps features [default: $XDG_CACHE_HOME/vkdiff/fid or ~/.cache/vkdiff/fid].
    #[arg(long)]
    cache_dir: Option<PathBuf>,
    /// KID subsets (torch-fidelity's `kid_subsets`).
    #[arg(long, default_value_t = 100)]
    kid_subsets: usize,
    /// Images per KID subset (torch-fidelity's `kid_subset_size`); clamped, with a warning, to the
    /// smaller set's size where torch-fidelity would refuse.
    #[arg(long, default_value_t = 1000)]
    kid_subset_size: usize,
    /// Images per Inception batch on the device.
    #[arg(long, default_value_t = 8)]
    batch: usize,
    /// f32 matches torch-fidelity to ~1e-6; f16 is faster on GPUs and off by ~1e-3 in features.
    #[arg(long, value_enum, default_value_t = Precision::F32)]
    precision: Precision,
    #[command(flatten)]
    device: vkdiff_args::DeviceArgs,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
}

pub fn run(args: &FidArgs, env: &vkdiff_runtime::Environment) -> Result<()> {
    let cache = match (&args.cache_dir, args.cache) {
        (Some(dir), _) => CacheDir::At(dir.clone()),
        (None, true) => CacheDir::Default { base: user_cache_base(env) },
        (None, false) => CacheDir::Off,
    };
    let job = FidJob::new(FidRequest {
        real: args.real.clone(),
        fake: args.fake.clone(),
        inception: vkdiff_args::resolve_model("--inception", &args.inception, vkdiff_args::Wants::File, env)?,
        dtype: args.precision.dtype(),
        batch: args.batch,
        kid_subsets: args.kid_subsets,
        kid_subset_size: args.kid_subset_size,
        cache,
    })?;
    if let Some(warning) = job.warning() {
        eprintln!("{warning}");
    }
    let ctx = crate::open_device(&args.device, env)?;
    let mut bar: Option<(&str, Progress)> = None;
    let out = job.run(&ctx, &mut |stage, done, total| {
        if bar.as_ref().is_none_or(|(shown, _)| *shown != stage) {
            bar = Some((stage, Progress::new(stage, "image")));
        }
        if let Some((_, bar)) = &bar {
            bar.update(done, total);
        }
    })?;
    let k = &out.kid;
    if args.json {
        let side = |dir: &Path, f: &FolderFeatures| {
            serde_json::json!({
                "dir": dir.display().to_string(),
                "images": f.images,
                "cached": f.cached,
            })
        };
        let json = serde_json::json!({
            "fid": out.fid,
            "kid_mean": k.mean,
            "kid_std": k.std,
            "kid_subsets": args.kid_subsets,
            "kid_subset_size": k.subset_size,
            "real": side(&args.real, &out.real),
            "fake": side(&args.fake, &out.fake),
            "precision": format!("{:?}", args.precision).to_lowercase(),
        });
        println!("{}", serde_json::to_string_pretty(&json)?);
        return Ok(());
    }
    let cached = |n: usize| if n > 0 { format!(", {n} from the cache") } else { String::new() };
    println!(
        "real {} ({} images{}), fake {} ({} images{})",
        args.real.display(),
        out.real.images,
        cached(out.real.cached),
        args.fake.display(),
        out.fake.images,
        cached(out.fake.cached)
    );
    println!("FID       {:.4}", out.fid);
    println!("KID_mean  {:.6}", k.mean);
    println!("KID_std   {:.6}   ({} subsets of {})", k.std, args.kid_subsets, k.subset_size);
    Ok(())
}
