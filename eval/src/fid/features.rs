//! Image folders to Inception features on the Vulkan device, found and read as torch-fidelity finds
//! and reads them: the folder's own `png`, `jpg` and `jpeg` files (any case, not recursive),
//! sorted by full path, each `PIL.Image.open(f).convert("RGB")`.

use super::cache::FeatureCache;
use crate::{EvalError, Result};
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use vkdiff_formats::{Error as FileError, SafeTensors, TorchPth};
use vkdiff_networks::{InceptionV3, RgbPixels, TensorSource, INCEPTION_FEATURES};
use vkdiff_runtime::{Context, Dtype};
use vkdiff_setting::Message;

/// The extensions torch-fidelity's `samples_find_ext` defaults to.
const EXTENSIONS: [&str; 3] = ["png", "jpg", "jpeg"];

/// An Inception weights file: torch's `.pth` (zip or legacy) or safetensors, told apart by content.
pub fn open_weights(path: &Path) -> Result<Box<dyn TensorSource>> {
    let mut head = [0u8; 8];
    let read = std::fs::File::open(path).and_then(|mut f| std::io::Read::read(&mut f, &mut head));
    let n = read.map_err(|source| FileError::Io { path: path.to_path_buf(), source })?;
    // A zip archive (torch ≥ 1.6) or a pickle (the legacy format) is torch's; anything else is
    // tried as safetensors, whose own checks name what is wrong.
    if head[..n].starts_with(b"PK") || head[..n].starts_with(&[0x80]) {
        Ok(Box::new(TorchPth::open(path)?))
    } else {
        Ok(Box::new(SafeTensors::open(path)?))
    }
}

/// The images of `dir` as torch-fidelity lists them. A `vkdiff dataset` folder stands for its
/// `images/`.
pub fn list_images(dir: &Path) -> Result<Vec<PathBuf>> {
    let dir = if dir.join("dataset.json").is_file() && dir.join("images").is_dir() {
        dir.join("images")
    } else {
        dir.to_path_buf()
    };
    let unlisted = |source| FileError::Io { path: dir.clone(), source };
    let entries = std::fs::read_dir(&dir).map_err(unlisted)?;
    let mut files = Vec::new();
    for entry in entries {
        let path = entry.map_err(unlisted)?.path();
        let ext = path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase());
        if path.is_file() && ext.is_some_and(|e| EXTENSIONS.contains(&e.as_str())) {
            files.push(std::fs::canonicalize(&path).unwrap_or(path));
        }
    }
    files.sort();
    Ok(files)
}

/// Images decoded in parallel, as the encoder reads them.
fn read_images(files: &[&Path]) -> Vec<vkdiff_formats::Result<vkdiff_formats::RgbImage>> {
    files.par_iter().map(|f| vkdiff_formats::image::read_image(f)).collect()
}

/// Reads every file as the encoder will, before anything is encoded, so that a bad file costs
/// seconds, not the encoding of the folders before it; the error names every file that cannot
/// be read. `progress(done, total)` as files are read.
pub fn check_images(files: &[&Path], progress: &mut dyn FnMut(usize, usize)) -> Result<()> {
    let mut bad = Vec::new();
    progress(0, files.len());
    for (i, chunk) in files.chunks(64).enumerate() {
        bad.extend(read_images(chunk).into_iter().filter_map(std::result::Result::err));
        progress((i * 64 + chunk.len()).min(files.len()), files.len());
    }
    if bad.is_empty() {
        return Ok(());
    }
    Err(EvalError::Unreadable { errors: bad, total: files.len() })
}

/// torch-fidelity's InceptionV3 on a device, a batch of images at a time.
pub struct FeatureExtractor {
    net: InceptionV3,
    batch: usize,
    /// What the cache keys features by besides the file: weights and precision.
    pub fingerprint: String,
}

impl FeatureExtractor {
    pub fn new(ctx: &Context, weights: &Path, dtype: Dtype, batch: usize) -> Result<FeatureExtractor> {
        let src = open_weights(weights)?;
        let net = InceptionV3::load(ctx, dtype, src.as_ref())
            .map_err(|e| EvalError::from(e).context(weights.display().to_string()))?;
        Ok(FeatureExtractor { net, batch: batch.max(1), fingerprint: format!("{} {dtype:?}", file_stamp(weights)?) })
    }

    /// Features of `files` ([files × 2048]), taking what `cache` holds and adding what it lacks;
    /// `progress(done, total)` after each batch.
    pub fn features(
        &self,
        files: &[PathBuf],
        mut cache: Option<&mut FeatureCache>,
        progress: &mut dyn FnMut(usize, usize),
    ) -> Result<Vec<f32>> {
        let mut rows: Vec<Option<Vec<f32>>> = files.iter().map(|f| cache.as_mut().and_then(|c| c.get(f))).collect();
        let missing: Vec<usize> = (0..files.len()).filter(|&i| rows[i].is_none()).collect();
        let mut done = files.len() - missing.len();
        progress(done, files.len());
        for chunk in missing.chunks(self.batch) {
            let paths: Vec<&Path> = chunk.iter().map(|&i| files[i].as_path()).collect();
            let images = read_images(&paths).into_iter().collect::<vkdiff_formats::Result<Vec<_>>>()?;
            let pixels: Vec<RgbPixels> =
                images.iter().map(|m| RgbPixels { data: &m.pixels, width: m.width, height: m.height }).collect();
            let features = self.net.features(&pixels)?;
            for (&i, row) in chunk.iter().zip(features.chunks_exact(INCEPTION_FEATURES)) {
                if row.iter().any(|v| !v.is_finite()) {
                    return Err(EvalError::Setting(
                        Message::text(format!("{}: Inception features are not finite (try ", files[i].display()))
                            .and("precision")
                            .then(" f32)"),
                    ));
                }
                rows[i] = Some(row.to_vec());
            }
            done += chunk.len();
            progress(done, files.len());
        }
        let rows: Vec<Vec<f32>> = rows.into_iter().map(|r| r.expect("every missing row was computed")).collect();
        if let Some(c) = cache {
            c.store(files, &rows)?;
        }
        Ok(rows.concat())
    }
}

/// A file's identity for caches: canonical path, size and modification time.
pub fn file_stamp(path: &Path) -> Result<String> {
    let meta = std::fs::metadata(path).map_err(|source| FileError::Io { path: path.to_path_buf(), source })?;
    let modified =
        meta.modified().ok().and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok()).map_or(0, |d| d.as_nanos());
    let full = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf());
    Ok(format!("{} {} {modified}", full.display(), meta.len()))
}
