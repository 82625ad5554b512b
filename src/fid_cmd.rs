//! `vkdiff fid`: FID and KID between a folder of real photos and a folder of generated images, as
//! torch-fidelity computes them (`fidelity --fid --kid --input1 FAKE --input2 REAL`), with its
//! InceptionV3 running on the Vulkan device.

use crate::model_args::Precision;
use crate::progress::Progress;
use anyhow::{bail, ensure, Context as _, Result};
use std::path::{Path, PathBuf};
use vkdiff_eval::fid::{check_images, fid, kid, list_images, FeatureCache, FeatureExtractor, KidOptions};
use vkdiff_networks::INCEPTION_FEATURES;

#[derive(clap::Args)]
pub struct FidArgs {
    /// The real photos (png, jpg, jpeg; not recursive).
    real: PathBuf,
    /// The generated images, or a `vkdiff dataset` folder (its images/).
    fake: PathBuf,
    /// torch-fidelity's InceptionV3 weights, `weights-inception-2015-12-05-6726825d.pth` as torch
    /// saved it, or the same tensors as .safetensors.
    #[arg(long)]
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
    /// Vulkan device index (see `vkdiff devices`).
    #[arg(long)]
    device: Option<usize>,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
}

fn default_cache_dir() -> Result<PathBuf> {
    let base = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")));
    Ok(base.context("--cache: neither XDG_CACHE_HOME nor HOME is set; give --cache-dir")?.join("vkdiff/fid"))
}

/// The images of a folder given on the command line, refused unless there are at least two.
fn images_of(dir: &Path, what: &str) -> Result<Vec<PathBuf>> {
    ensure!(dir.is_dir(), "{what} {}: not a folder", dir.display());
    let files = list_images(dir)?;
    ensure!(
        files.len() >= 2,
        "{what} {}: {} png/jpg/jpeg images; FID and KID need at least 2",
        dir.display(),
        files.len()
    );
    Ok(files)
}

pub fn run(args: &FidArgs) -> Result<()> {
    ensure!(
        args.inception.is_file(),
        "--inception {}: no such file (torch-fidelity's weights-inception-2015-12-05-6726825d.pth)",
        args.inception.display()
    );
    ensure!(
        args.kid_subsets > 0 && args.kid_subset_size > 1,
        "--kid-subsets must be positive and --kid-subset-size at least 2"
    );
    ensure!(args.batch > 0, "--batch must be positive");
    let real = images_of(&args.real, "real")?;
    let fake = images_of(&args.fake, "fake")?;
    let cache_dir = match (&args.cache_dir, args.cache) {
        (Some(d), _) => Some(d.clone()),
        (None, true) => Some(default_cache_dir()?),
        (None, false) => None,
    };
    let subset_size = args.kid_subset_size.min(real.len()).min(fake.len());
    if subset_size < args.kid_subset_size {
        eprintln!("warning: KID subsets of {subset_size} images, not {}: the smaller set has {subset_size} (torch-fidelity would refuse; pass --kid-subset-size {subset_size} to it to compare)", args.kid_subset_size);
    }

    let ctx = vkdiff_runtime::Context::new(args.device)?;
    let extractor = FeatureExtractor::new(&ctx, &args.inception, args.precision.dtype(), args.batch)?;
    let open_cache =
        |dir: &Path| cache_dir.as_ref().map(|d| FeatureCache::open(d, dir, &extractor.fingerprint)).transpose();
    let (mut real_cache, mut fake_cache) = (open_cache(&args.real)?, open_cache(&args.fake)?);
    // Every file the network will read, of both folders, is read once before any encoding.
    let uncached = |files: &[PathBuf], cache: &Option<FeatureCache>| -> Vec<PathBuf> {
        files.iter().filter(|f| !cache.as_ref().is_some_and(|c| c.has(f))).cloned().collect()
    };
    let unchecked = [uncached(&real, &real_cache), uncached(&fake, &fake_cache)].concat();
    if !unchecked.is_empty() {
        let bar = Progress::new("reading", "image");
        check_images(&unchecked.iter().map(PathBuf::as_path).collect::<Vec<_>>(), &mut |done, total| {
            bar.update(done, total)
        })?;
    }
    let encode =
        |files: &[PathBuf], mut cache: Option<FeatureCache>, label: &'static str| -> Result<(Vec<f32>, usize)> {
            let bar = Progress::new(label, "image");
            let features = extractor.features(files, cache.as_mut(), &mut |done, total| bar.update(done, total))?;
            Ok((features, cache.map_or(0, |c| c.hits)))
        };
    let (real_features, real_cached) = encode(&real, real_cache.take(), "real")?;
    let (fake_features, fake_cached) = encode(&fake, fake_cache.take(), "fake")?;

    let fid_value = fid(&fake_features, &real_features, INCEPTION_FEATURES)?;
    let opts = KidOptions { subsets: args.kid_subsets, subset_size, ..KidOptions::default() };
    // torch-fidelity draws each KID subset from input1 (the generated set) first.
    let k = kid(&fake_features, &real_features, INCEPTION_FEATURES, &opts)?;
    if !fid_value.is_finite() {
        bail!("FID is not finite: the features hold NaN or infinity");
    }
    if args.json {
        let side = |dir: &Path, n: usize, cached: usize| serde_json::json!({ "dir": dir.display().to_string(), "images": n, "cached": cached });
        let out = serde_json::json!({
            "fid": fid_value,
            "kid_mean": k.mean,
            "kid_std": k.std,
            "kid_subsets": args.kid_subsets,
            "kid_subset_size": k.subset_size,
            "real": side(&args.real, real.len(), real_cached),
            "fake": side(&args.fake, fake.len(), fake_cached),
            "precision": format!("{:?}", args.precision).to_lowercase(),
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    let cached = |n: usize| if n > 0 { format!(", {n} from the cache") } else { String::new() };
    println!(
        "real {} ({} images{}), fake {} ({} images{})",
        args.real.display(),
        real.len(),
        cached(real_cached),
        args.fake.display(),
        fake.len(),
        cached(fake_cached)
    );
    println!("FID       {fid_value:.4}");
    println!("KID_mean  {:.6}", k.mean);
    println!("KID_std   {:.6}   ({} subsets of {})", k.std, args.kid_subsets, k.subset_size);
    Ok(())
}
