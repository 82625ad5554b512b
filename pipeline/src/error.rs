use vkdiff_setting::Message;

/// What driving the networks can fail with; each message is one line naming the file or setting
/// at fault.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A setting (sampler, scheduler, size, …) that cannot be used as given.
    #[error("{0}")]
    Config(String),
    /// A setting refused, every setting it names kept as data (printed as the front end says).
    #[error("{0}")]
    Setting(Message),
    /// A network's output that is not a number: never written out as a black image.
    #[error(
        "{stage} holds NaN or infinite values; f16 may have overflowed there: try {} f32",
        Message::setting("precision")
    )]
    NotFinite { stage: String },
    /// An error prefixed by what it happened to (a setting and its file).
    #[error("{0}: {1}")]
    Context(Message, Box<Error>),
    #[error(transparent)]
    File(#[from] vkdiff_formats::Error),
    #[error(transparent)]
    Network(#[from] vkdiff_networks::Error),
    #[error(transparent)]
    Lora(#[from] vkdiff_lora::Error),
    #[error(transparent)]
    Render(#[from] vkdiff_render::RenderError),
    #[error(transparent)]
    Runtime(#[from] vkdiff_runtime::Error),
}

pub type Result<T> = std::result::Result<T, Error>;

/// `values` unchanged, or [`Error::NotFinite`] naming `stage`.
pub fn finite<'a>(values: &'a [f32], stage: &dyn Fn() -> String) -> Result<&'a [f32]> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(values)
    } else {
        Err(Error::NotFinite { stage: stage() })
    }
}
