//! How networks find their weights: checkpoints seen through diffusers names, the renamings of
//! original single-file layouts, config files, and the parameters placed on the device.

mod checkpoint;
mod config_file;
mod diffusers_files;
mod original_names;
mod parameters;

pub(crate) use checkpoint::transpose;
pub use checkpoint::{Checkpoint, Weights};
pub(crate) use config_file::read_config;
pub(crate) use diffusers_files::component_folder;
pub use original_names::{Inner, OriginalNames, StoredAs};
pub use parameters::{ParamLayout, Parameter, Parameters};
