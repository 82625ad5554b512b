//! A network's `config.json`, read with one error line naming the file.

use crate::error::{Error, Result};
use std::path::Path;

/// A diffusers/transformers config.json as `T`; `what` names the model kind in the error.
pub(crate) fn read_config<T: serde::de::DeserializeOwned>(path: &Path, what: &str) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::Io { path: path.to_path_buf(), source: e })?;
    serde_json::from_str(&text)
        .map_err(|e| Error::Format { path: path.to_path_buf(), why: format!("not {what} config: {e}") })
}
