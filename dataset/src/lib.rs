//! `vkdiff dataset`, the product: scenes (the procedural bed or scenes rendered elsewhere, from
//! `vkdiff-scenes`) turned into an annotated training set by `vkdiff-pipeline`'s SDXL, one folder
//! holding the generated images, each image's depth, control image and instance mask, and COCO
//! annotations. Resumable image by image, sharded by scene over any number of processes sharing
//! the folder, and merged into one `annotations.json` at the end; then exported to trainers'
//! formats, summarised and previewed.

mod audit;
mod audit_boundary;
mod audit_predictions;
mod audit_summary;
mod canvas;
mod controls;
mod disk;
mod error;
mod export;
mod finish;
mod folder;
mod job;
mod merge;
mod plan;
mod preview;
mod preview_flagged;
mod preview_geometry;
mod preview_page;
mod preview_pictures;
mod regenerate;
mod regions;
mod render_only;
mod run;
mod scenes;
mod settings;
mod settings_record;
mod stats;
mod stats_geometry;
mod stop;

pub use audit::{audit, AuditOptions, Audited, AUDIT, KINDS as AUDIT_KINDS};
pub use audit_predictions::{read_predictions, PredictionFormat, SetIndex};
pub use controls::{control_file, LabelControls};
pub use disk::{parse_size, size, DiskGuard, DEFAULT_MIN_FREE};
pub use error::{Error, Result};
pub use export::{
    export, BopWritten, Exclusion, ExportFormat, ExportOptions, Exported, PolygonFit, Split, SplitFractions, EXCLUDED,
};
pub use folder::{Dataset, ImageRecord, Pending, VersionChange, ANNOTATIONS, MANIFEST};
pub use job::{DatasetEvent, DatasetJob, Finish, ShardRequest};
pub use merge::{merge, Merged};
pub use plan::{choose, image_seed, Choice, ImageFiles, Shard};
pub use preview::{preview, Preview};
pub use preview_pictures::escape as html_escape;
pub use regenerate::RESAMPLES;
pub use regions::{RegionFlags, RegionSettings};
pub use run::{generate, Progress, Report, RunOptions, StageTimes};
pub use settings::{read_prompts, Crops, DatasetSettings};
pub use stats::{stats, write_charts};
pub use stop::{stop_on_signals, stop_requested};
pub use vkdiff_scenes::{ProceduralBed, RenderedScenes, SceneError, SceneSource, DEFAULT_FAR};
