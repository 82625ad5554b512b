//! A network's `config.json`, read with one error line naming the file.

use crate::error::Result;
use std::path::Path;
use vkdiff_formats::Error as FileError;

/// A diffusers/transformers config.json as `T`; `what` names the model kind in the error.
pub(crate) fn read_config<T: serde::de::DeserializeOwned>(path: &Path, what: &str) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|e| FileError::Io { path: path.to_path_buf(), source: e })?;
    Ok(serde_json::from_str(&text)
        .map_err(|e| FileError::Format { path: path.to_path_buf(), why: format!("not {what} config: {e}") })?)
}
