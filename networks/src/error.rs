/// What loading or running a network can fail with; each message is one line naming the file,
/// tensor or setting at fault.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A tensor that is missing, has the wrong shape or an unreadable dtype.
    #[error("{0}")]
    Checkpoint(String),
    /// A config value vkdiff cannot build a network from.
    #[error("{0}")]
    Config(String),
    #[error(transparent)]
    File(#[from] vkdiff_formats::Error),
    #[error(transparent)]
    Runtime(#[from] vkdiff_runtime::Error),
}

pub type Result<T> = std::result::Result<T, Error>;
