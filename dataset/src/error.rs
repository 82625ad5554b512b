use vkdiff_setting::Message;

/// What making, merging or reading a dataset can fail with; each message is one line naming the
/// file, scene or setting at fault. Generation's own errors (networks, LoRA, the device, a
/// number that is none) come as [`Error::Pipeline`].
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A setting that cannot be used as given.
    #[error("{0}")]
    Config(String),
    /// A setting refused, every setting it names kept as data (printed as the front end says).
    #[error("{0}")]
    Setting(Message),
    /// The disk (or its `--min-free` margin) is full: the same command resumes once there is room.
    #[error("{0}")]
    DiskFull(Message),
    /// A signal asked the run to stop; what was finished stays, and the same command resumes.
    #[error("{0}")]
    Interrupted(String),
    /// An error prefixed by what it happened to (a setting and its file).
    #[error("{0}: {1}")]
    Context(Message, Box<Error>),
    #[error(transparent)]
    File(#[from] vkdiff_formats::Error),
    #[error(transparent)]
    Render(#[from] vkdiff_render::RenderError),
    #[error(transparent)]
    Scenes(#[from] vkdiff_scenes::Error),
    #[error(transparent)]
    Pipeline(#[from] vkdiff_pipeline::Error),
    #[error(transparent)]
    Eval(#[from] vkdiff_eval::EvalError),
}

pub type Result<T> = std::result::Result<T, Error>;
