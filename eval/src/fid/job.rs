//! `vkdiff fid`'s one entry: both folders listed and every setting checked before the device
//! opens; every uncached image of both folders read once before any encoding; features through
//! the per-folder cache; then FID and KID as torch-fidelity computes them
//! (`fidelity --fid --kid --input1 FAKE --input2 REAL`).

use crate::fid::cache::FeatureCache;
use crate::fid::features::{check_images, list_images, FeatureExtractor};
use crate::fid::stats::{fid, kid, Kid, KidOptions};
use crate::{EvalError, Result};
use std::path::{Path, PathBuf};
use vkdiff_networks::INCEPTION_FEATURES;
use vkdiff_runtime::{Context, Dtype};
use vkdiff_setting::{Environment, Message};

/// What to compare and how.
pub struct FidRequest {
    pub real: PathBuf,
    pub fake: PathBuf,
    /// torch-fidelity's InceptionV3 weights (`.pth` or `.safetensors`).
    pub inception: PathBuf,
    pub dtype: Dtype,
    /// Images per Inception batch.
    pub batch: usize,
    pub kid_subsets: usize,
    /// Images per KID subset, as asked; clamped to the smaller set's size.
    pub kid_subset_size: usize,
    /// Where each folder's features are kept and reused.
    pub cache: CacheDir,
}

/// Where features are cached.
pub enum CacheDir {
    Off,
    /// `vkdiff/fid` in the user's cache folder, as [`user_cache_base`] found it at the edge.
    Default {
        base: Option<PathBuf>,
    },
    At(PathBuf),
}

/// The user's cache folder in `env`: `$XDG_CACHE_HOME`, else `~/.cache`; None where neither
/// variable is set.
pub fn user_cache_base(env: &Environment) -> Option<PathBuf> {
    env.raw("XDG_CACHE_HOME").map(PathBuf::from).or_else(|| env.raw("HOME").map(|h| PathBuf::from(h).join(".cache")))
}

fn default_cache_dir(base: Option<&Path>) -> Result<PathBuf> {
    let base = base.ok_or_else(|| {
        EvalError::Setting(
            Message::setting("cache").then(": neither XDG_CACHE_HOME nor HOME is set; give ").and("cache_dir"),
        )
    })?;
    Ok(base.join("vkdiff/fid"))
}

/// A checked request with both folders listed.
pub struct FidJob {
    request: FidRequest,
    cache_dir: Option<PathBuf>,
    real: Vec<PathBuf>,
    fake: Vec<PathBuf>,
    subset_size: usize,
}

/// One side of the comparison.
pub struct FolderFeatures {
    pub images: usize,
    /// Images whose features came from the cache.
    pub cached: usize,
}

pub struct FidOutcome {
    pub fid: f64,
    pub kid: Kid,
    pub real: FolderFeatures,
    pub fake: FolderFeatures,
}

/// The images of a folder, refused unless there are at least two.
fn images_of(dir: &Path, what: &str) -> Result<Vec<PathBuf>> {
    if !dir.is_dir() {
        return Err(EvalError::Invalid(format!("{what} {}: not a folder", dir.display())));
    }
    let files = list_images(dir)?;
    if files.len() < 2 {
        return Err(EvalError::Invalid(format!(
            "{what} {}: {} png/jpg/jpeg images; FID and KID need at least 2",
            dir.display(),
            files.len()
        )));
    }
    Ok(files)
}

impl FidJob {
    pub fn new(request: FidRequest) -> Result<FidJob> {
        if !request.inception.is_file() {
            return Err(EvalError::Setting(Message::setting("inception").then(format!(
                " {}: no such file (torch-fidelity's weights-inception-2015-12-05-6726825d.pth)",
                request.inception.display()
            ))));
        }
        if request.kid_subsets == 0 || request.kid_subset_size < 2 {
            return Err(EvalError::Setting(
                Message::setting("kid_subsets")
                    .then(" must be positive and ")
                    .and("kid_subset_size")
                    .then(" at least 2"),
            ));
        }
        if request.batch == 0 {
            return Err(EvalError::Setting(Message::setting("batch").then(" must be positive")));
        }
        let real = images_of(&request.real, "real")?;
        let fake = images_of(&request.fake, "fake")?;
        let cache_dir = match &request.cache {
            CacheDir::Off => None,
            CacheDir::Default { base } => Some(default_cache_dir(base.as_deref())?),
            CacheDir::At(dir) => Some(dir.clone()),
        };
        let subset_size = request.kid_subset_size.min(real.len()).min(fake.len());
        Ok(FidJob { request, cache_dir, real, fake, subset_size })
    }

    /// A warning when KID's subsets are smaller than asked (torch-fidelity would refuse).
    pub fn warning(&self) -> Option<String> {
        let asked = self.request.kid_subset_size;
        let size = self.subset_size;
        (size < asked).then(|| {
            format!(
                "warning: KID subsets of {size} images, not {asked}: the smaller set has \
            {size} (torch-fidelity would refuse; pass --kid-subset-size {size} to it to compare)"
            )
        })
    }

    /// Encodes both folders on `ctx` and computes FID and KID; `progress(stage, done, total)`
    /// hears each stage (`reading`, `real`, `fake`).
    pub fn run(&self, ctx: &Context, progress: &mut dyn FnMut(&'static str, usize, usize)) -> Result<FidOutcome> {
        let r = &self.request;
        let extractor = FeatureExtractor::new(ctx, &r.inception, r.dtype, r.batch)?;
        let open_cache = |dir: &Path| {
            self.cache_dir.as_ref().map(|d| FeatureCache::open(d, dir, &extractor.fingerprint)).transpose()
        };
        let (mut real_cache, mut fake_cache) = (open_cache(&r.real)?, open_cache(&r.fake)?);
        // Every file the network will read, of both folders, is read once before any encoding.
        let uncached = |files: &[PathBuf], cache: &Option<FeatureCache>| -> Vec<PathBuf> {
            files.iter().filter(|f| !cache.as_ref().is_some_and(|c| c.has(f))).cloned().collect()
        };
        let unchecked = [uncached(&self.real, &real_cache), uncached(&self.fake, &fake_cache)].concat();
        if !unchecked.is_empty() {
            let files: Vec<&Path> = unchecked.iter().map(PathBuf::as_path).collect();
            check_images(&files, &mut |done, total| progress("reading", done, total))?;
        }
        let mut encode = |files: &[PathBuf], mut cache: Option<FeatureCache>, stage: &'static str| {
            let features =
                extractor.features(files, cache.as_mut(), &mut |done, total| progress(stage, done, total))?;
            let side = FolderFeatures { images: files.len(), cached: cache.map_or(0, |c| c.hits) };
            Ok::<_, EvalError>((features, side))
        };
        let (real_features, real) = encode(&self.real, real_cache.take(), "real")?;
        let (fake_features, fake) = encode(&self.fake, fake_cache.take(), "fake")?;
        let fid_value = fid(&fake_features, &real_features, INCEPTION_FEATURES)?;
        let opts = KidOptions { subsets: r.kid_subsets, subset_size: self.subset_size, ..KidOptions::default() };
        // torch-fidelity draws each KID subset from input1 (the generated set) first.
        let kid = kid(&fake_features, &real_features, INCEPTION_FEATURES, &opts)?;
        if !fid_value.is_finite() {
            return Err(EvalError::NotFinite("FID is not finite: the features hold NaN or infinity".into()));
        }
        Ok(FidOutcome { fid: fid_value, kid, real, fake })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_cache_is_under_xdg_cache_home_else_home() {
        let env = |pairs: &[(&str, &str)]| Environment::from_pairs(pairs.iter().copied());
        let both = env(&[("XDG_CACHE_HOME", "/x"), ("HOME", "/h")]);
        assert_eq!(user_cache_base(&both), Some(PathBuf::from("/x")));
        assert_eq!(user_cache_base(&env(&[("HOME", "/h")])), Some(PathBuf::from("/h/.cache")));
        assert_eq!(user_cache_base(&env(&[])), None);
        assert_eq!(default_cache_dir(Some(Path::new("/x"))).unwrap(), PathBuf::from("/x/vkdiff/fid"));
        let err = default_cache_dir(None).unwrap_err().to_string();
        assert!(err.contains("neither XDG_CACHE_HOME nor HOME is set"), "{err}");
    }
}
