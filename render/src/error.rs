//! Errors of the render library: each names the flag, value or file that is wrong, in one line.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// A user-supplied setting is out of range; `flag` is the command-line spelling.
    #[error("{flag} {value}: {reason}")]
    InvalidArgument { flag: &'static str, value: String, reason: String },

    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },

    #[error("{path}: output exists already (pass --force to replace it)")]
    OutputExists { path: PathBuf },

    #[error("the bed holds {count} mushrooms, more than the 65534 ids of a 16-bit instances.png; lower --density")]
    TooManyInstances { count: usize },
}

impl RenderError {
    pub fn invalid(flag: &'static str, value: impl ToString, reason: impl Into<String>) -> Self {
        RenderError::InvalidArgument { flag, value: value.to_string(), reason: reason.into() }
    }

    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        RenderError::Io { path: path.into(), source }
    }
}

pub type Result<T> = std::result::Result<T, RenderError>;
