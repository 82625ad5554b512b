//! Where a diffusers component's weights are: its folder (a pipeline's subfolder or the
//! component itself), and its one file or the shards its index lists, fp16 variant or not.

use crate::error::{Error, Result};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use vkdiff_formats::Error as FileError;
use vkdiff_formats::SafeTensors;
use vkdiff_runtime::Dtype;

pub(crate) fn component_folder(dir: &Path, sub: &str) -> Result<PathBuf> {
    let folder = if dir.join(sub).join("config.json").is_file() { dir.join(sub) } else { dir.to_path_buf() };
    if !folder.join("config.json").is_file() {
        return Err(Error::Checkpoint(format!(
            "{}: no config.json (expected a diffusers model folder or its {sub}/ subfolder)",
            dir.display()
        )));
    }
    Ok(folder)
}

/// The weight files of a diffusers component: one file or shards listed by an index, preferring
/// the fp16 variant for f16 runs and the full-precision one for f32 runs.
pub(super) fn diffusers_weight_files(dir: &Path, stem: &str, dtype: Dtype) -> Result<Vec<SafeTensors>> {
    let plain = [format!("{stem}.safetensors"), format!("{stem}.safetensors.index.json")];
    let fp16 = [format!("{stem}.fp16.safetensors"), format!("{stem}.safetensors.index.fp16.json")];
    let order = if dtype == Dtype::F16 { [fp16, plain] } else { [plain, fp16] };
    for [single, index] in &order {
        if dir.join(single).is_file() {
            return Ok(vec![SafeTensors::open(&dir.join(single))?]);
        }
        if dir.join(index).is_file() {
            return shards(&dir.join(index));
        }
    }
    Err(Error::Checkpoint(format!("{}: no {stem}[.fp16].safetensors or sharded index", dir.display())))
}

fn shards(index_path: &Path) -> Result<Vec<SafeTensors>> {
    let bad = |why: String| Error::from(FileError::Format { path: index_path.to_path_buf(), why });
    let text =
        std::fs::read_to_string(index_path).map_err(|e| FileError::Io { path: index_path.to_path_buf(), source: e })?;
    let json: serde_json::Value = serde_json::from_str(&text).map_err(|e| bad(format!("not JSON: {e}")))?;
    let map = json.get("weight_map").and_then(|m| m.as_object()).ok_or_else(|| bad("no `weight_map`".into()))?;
    let names: BTreeSet<&str> = map.values().filter_map(|v| v.as_str()).collect();
    let dir: PathBuf = index_path.parent().unwrap_or(Path::new(".")).to_path_buf();
    let files = names.iter().map(|n| SafeTensors::open(&dir.join(n))).collect::<vkdiff_formats::Result<Vec<_>>>()?;
    for (tensor, file) in map {
        let f = files.iter().find(|f| f.path.file_name().and_then(|s| s.to_str()) == file.as_str());
        if !f.is_some_and(|f| f.entries.contains_key(tensor)) {
            return Err(bad(format!("tensor `{tensor}` is listed in {file} but that shard does not hold it")));
        }
    }
    Ok(files)
}
