//! How networks find their weights: checkpoints seen through diffusers names, the renamings of
//! original single-file layouts, config files, and the parameters placed on the device.

mod checkpoint;
mod config_file;
mod original_names;
mod parameters;

pub(crate) use checkpoint::component_folder;
pub(crate) use checkpoint::transpose;
pub use checkpoint::{Checkpoint, Weights};
pub(crate) use config_file::read_config;
pub use original_names::{Inner, OriginalNames, StoredAs};
pub use parameters::{ParamLayout, Parameter, Parameters};
