//! Errors of the render library: each names the flag, value or file that is wrong, in one line.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// A user-supplied setting is out of range; `flag` is the command-line spelling.
    #[error("{flag} {value}: {reason}")]
    InvalidArgument { flag: &'static str, value: String, reason: String },

    /// `error` is deliberately not a `#[source]`: its text is already in the one line.
    #[error("cannot {action} {path}: {error}")]
    Io { action: &'static str, path: PathBuf, error: std::io::Error },

    #[error("{path}: output exists already (pass --force to replace it)")]
    OutputExists { path: PathBuf },

    #[error("the bed holds {count} mushrooms, more than the 65534 ids of a 16-bit instances.png; lower --density")]
    TooManyInstances { count: usize },
}

impl RenderError {
    pub fn invalid(flag: &'static str, value: impl ToString, reason: impl Into<String>) -> Self {
        RenderError::InvalidArgument { flag, value: value.to_string(), reason: reason.into() }
    }

    pub fn io(action: &'static str, path: impl Into<PathBuf>, error: std::io::Error) -> Self {
        RenderError::Io { action, path: path.into(), error }
    }
}

pub type Result<T> = std::result::Result<T, RenderError>;
