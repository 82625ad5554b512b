//! Errors of the render library: each names the setting, value or file that is wrong, in one line.

use std::path::PathBuf;
use vkdiff_setting::Message;

#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// A setting out of range, named as data.
    #[error("{0}")]
    Setting(Message),

    /// `error` is deliberately not a `#[source]`: its text is already in the one line.
    #[error("cannot {action} {path}: {error}")]
    Io { action: &'static str, path: PathBuf, error: std::io::Error },

    #[error("{path}: output exists already (pass {} to replace it)", Message::setting("replace"))]
    OutputExists { path: PathBuf },

    #[error(
        "the bed holds {count} mushrooms, more than the 65534 ids of a 16-bit instances.png; lower {}",
        Message::setting("density")
    )]
    TooManyInstances { count: usize },
}

impl RenderError {
    /// `setting`'s `value` is refused for `reason`.
    pub fn invalid(setting: &'static str, value: impl ToString, reason: impl Into<String>) -> Self {
        RenderError::Setting(Message::setting(setting).then(format!(" {}: {}", value.to_string(), reason.into())))
    }

    pub fn io(action: &'static str, path: impl Into<PathBuf>, error: std::io::Error) -> Self {
        RenderError::Io { action, path: path.into(), error }
    }
}

pub type Result<T> = std::result::Result<T, RenderError>;
