//! COCO evaluation on the CPU: ground truth and results read from COCO JSON, masks as COCO
//! run-length encodings, and `COCOeval`'s matching, accumulation and twelve statistics computed
//! as pycocotools does (held to it by `tests/`).

mod cocoeval;
mod dataset;
pub mod fid;
mod masks;
mod summary;

pub use cocoeval::{evaluate, EvalParams, IouType, Stats};
pub use dataset::{Annotation, AreaRule, AreaSource, Dataset, Geometry};
pub use masks::{bbox_iou, foreground_iou, mask_iou, polygon_rle, union};
pub use summary::{summarize, CategoryScores, Summary, SummaryRequest};
use vkdiff_setting::Message;

/// What evaluation can fail with, in one line.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// An input (file, JSON, image) that cannot be evaluated.
    #[error("{0}")]
    Invalid(String),
    /// A setting refused, every setting it names kept as data.
    #[error("{0}")]
    Setting(Message),
}

pub type Result<T> = std::result::Result<T, EvalError>;
