use std::path::PathBuf;

/// What reading a file can fail with; each message is one line naming the file and what is wrong.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{}: {source}", path.display())]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{}: {why}", path.display())]
    Format { path: PathBuf, why: String },
    /// A tensor that is missing from a file or stored in a type vkdiff does not read.
    #[error("{0}")]
    Tensor(String),
}

pub type Result<T> = std::result::Result<T, Error>;
