//! Inception features kept per image folder, so a folder of real photos is encoded once for every
//! comparison against it (the paper's ablation compares eight generated sets with one real set).
//! One safetensors file per folder, weights and precision: the features as rows, and which file
//! each row belongs to (path, size, modification time) in the metadata. An image whose file
//! changed, or is new, is encoded again, and so is every image when another vkdiff version made
//! the file; the file is rewritten atomically.

use super::features::file_stamp;
use crate::{EvalError, Result};
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use vkdiff_formats::{write_safetensors_f32, SafeTensors};
use vkdiff_networks::INCEPTION_FEATURES;
use vkdiff_setting::Message;

pub struct FeatureCache {
    path: PathBuf,
    /// File stamp → its features.
    rows: HashMap<String, Vec<f32>>,
    /// The stamps the file on disk holds, in order: storing the same list again writes nothing.
    loaded_stamps: Vec<String>,
    fingerprint: String,
    pub hits: usize,
}

impl FeatureCache {
    /// The cache of `folder` under `cache_dir` for features made with `fingerprint` (weights and
    /// precision); an unreadable or stale cache file is treated as empty.
    pub fn open(cache_dir: &Path, folder: &Path, fingerprint: &str) -> Result<FeatureCache> {
        std::fs::create_dir_all(cache_dir).map_err(|source| EvalError::Io {
            what: Message::setting("cache_dir").then(format!(" {}", cache_dir.display())),
            source,
        })?;
        let folder = std::fs::canonicalize(folder).unwrap_or_else(|_| folder.to_path_buf());
        let key = fnv1a64(format!("{}\n{fingerprint}", folder.display()).as_bytes());
        let name = folder.file_name().map_or("root".into(), |n| n.to_string_lossy().into_owned());
        let path = cache_dir.join(format!("{name}-{key:016x}.safetensors"));
        let mut cache = FeatureCache {
            path,
            rows: HashMap::new(),
            loaded_stamps: Vec::new(),
            fingerprint: fingerprint.to_string(),
            hits: 0,
        };
        if let Ok(file) = SafeTensors::open(&cache.path) {
            cache.load(&file);
        }
        Ok(cache)
    }

    fn load(&mut self, file: &SafeTensors) {
        let stamps: Option<Vec<String>> = file.metadata.get("files").and_then(|s| serde_json::from_str(s).ok());
        let (Some(stamps), Some(fp)) = (stamps, file.metadata.get("fingerprint")) else { return };
        let Ok((shape, values)) = file.values("features") else { return };
        // Another build's kernels may give other features: recompute them.
        let same_build = file.metadata.get("vkdiff").is_some_and(|v| v == vkdiff_setting::version());
        if *fp != self.fingerprint || !same_build || shape != [stamps.len(), INCEPTION_FEATURES] {
            return;
        }
        self.rows = stamps.iter().cloned().zip(values.chunks_exact(INCEPTION_FEATURES).map(<[f32]>::to_vec)).collect();
        self.loaded_stamps = stamps;
    }

    /// Whether the cache holds `file`'s features, unchanged since they were computed.
    pub fn has(&self, file: &Path) -> bool {
        file_stamp(file).is_ok_and(|stamp| self.rows.contains_key(&stamp))
    }

    /// The cached features of `file`, if it is unchanged since they were computed.
    pub fn get(&mut self, file: &Path) -> Option<Vec<f32>> {
        let row = self.rows.get(&file_stamp(file).ok()?).cloned();
        self.hits += row.is_some() as usize;
        row
    }

    /// Keeps exactly these files' features (rows in `files` order).
    pub fn store(&mut self, files: &[PathBuf], rows: &[Vec<f32>]) -> Result<()> {
        let stamps = files.iter().map(|f| file_stamp(f)).collect::<Result<Vec<_>>>()?;
        if stamps == self.loaded_stamps {
            return Ok(());
        }
        let metadata = BTreeMap::from([
            ("files".to_string(), serde_json::to_string(&stamps).expect("strings serialise")),
            ("fingerprint".to_string(), self.fingerprint.clone()),
            ("vkdiff".to_string(), vkdiff_setting::version().to_string()),
        ]);
        let values = rows.concat();
        write_safetensors_f32(&self.path, &[("features", &[files.len(), INCEPTION_FEATURES], &values)], &metadata)
            .map_err(|e| EvalError::from(e).context("cannot write the feature cache"))?;
        self.loaded_stamps = stamps;
        Ok(())
    }
}

fn fnv1a64(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| (h ^ b as u64).wrapping_mul(0x100_0000_01b3))
}
