//! COCO evaluation on the CPU: ground truth and results read from COCO JSON, masks as COCO
//! run-length encodings, keypoints scored by OKS, and `COCOeval`'s matching, accumulation and
//! statistics computed as pycocotools does (held to it by `tests/`).

mod cocoeval;
mod dataset;
pub mod fid;
mod keypoints;
mod masks;
mod matching;
mod summary;

pub use cocoeval::{evaluate, EvalParams, IouType, Stats};
pub use dataset::{Annotation, AreaRule, AreaSource, Dataset, Geometry};
pub use keypoints::{oks, COCO_PERSON_SIGMAS};
pub use masks::{bbox_iou, foreground_iou, mask_iou, polygon_rle, rle_iou, union};
pub use matching::{match_at, Matched, Matching};
pub use summary::{summarize, CategoryScores, Summary, SummaryRequest};
use vkdiff_setting::Message;

/// What evaluation can fail with, in one line; each kind kept apart, so that a bad input, a
/// failing device and a full disk stay distinguishable to whoever acts on the error.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// A file that cannot be read, written or parsed: its path and the reason.
    #[error(transparent)]
    File(#[from] vkdiff_formats::Error),
    /// A file or folder that cannot be read or written, named by what the message says of it
    /// (a setting and its path, or what was being read).
    #[error("{what}: {source}")]
    Io { what: Message, source: std::io::Error },
    /// An input (JSON, annotation, folder of images) that cannot be evaluated.
    #[error("{0}")]
    Invalid(String),
    /// A setting refused, every setting it names kept as data.
    #[error("{0}")]
    Setting(Message),
    /// Images that cannot be read, each named: a folder is read whole before any is encoded.
    #[error(
        "{} of {total} images cannot be read (nothing was encoded): {}",
        errors.len(),
        errors.iter().map(ToString::to_string).collect::<Vec<_>>().join("; ")
    )]
    Unreadable { errors: Vec<vkdiff_formats::Error>, total: usize },
    /// Inception's weights or its run on the device.
    #[error(transparent)]
    Network(#[from] vkdiff_networks::Error),
    /// Arithmetic that gave no number (an SVD that did not converge, a distance not finite).
    #[error("{0}")]
    NotFinite(String),
    /// An error prefixed by the file or the work it concerns.
    #[error("{what}: {source}")]
    Context { what: String, source: Box<EvalError> },
}

impl EvalError {
    /// `self`, prefixed by `what` (a file, a stage).
    pub fn context(self, what: impl Into<String>) -> EvalError {
        EvalError::Context { what: what.into(), source: Box::new(self) }
    }
}

pub type Result<T> = std::result::Result<T, EvalError>;
