use std::path::PathBuf;

/// What reading or merging a LoRA can fail with; each message is one line naming the file and
/// the tensor or module at fault.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A tensor of a LoRA-like format vkdiff does not merge (LoHa, LoKr, DoRA, ...).
    #[error(
        "{}: tensor `{key}` is {what}, which vkdiff cannot merge (it reads kohya and diffusers/PEFT LoRA)",
        path.display()
    )]
    Unsupported { path: PathBuf, key: String, what: String },
    /// LoRA modules that name no weight of the loaded networks.
    #[error("{}: {count} LoRA module(s) match no weight of the loaded networks: {listed}", path.display())]
    Unmatched { path: PathBuf, count: usize, listed: String },
    /// A module whose product does not have its weight's shape.
    #[error(
        "{}: module `{key}` makes a delta of shape {found:?} but `{weight}` has shape {expected:?}",
        path.display()
    )]
    Shape { path: PathBuf, key: String, weight: String, expected: Vec<usize>, found: Vec<usize> },
    #[error(transparent)]
    Network(#[from] vkdiff_networks::Error),
    #[error(transparent)]
    File(#[from] vkdiff_formats::Error),
    #[error(transparent)]
    Runtime(#[from] vkdiff_runtime::Error),
}

pub type Result<T> = std::result::Result<T, Error>;
