//! Every setting of a generation as data, shared by `gen` and `dataset`: the models, how each
//! image is sampled, the prompt syntax, prompt templates, the IP-Adapter's per-block scales, the
//! names they are recorded under, and `vkdiff gen`'s whole job.

mod gen;
pub(crate) mod ip_scale;
pub(crate) mod models;
pub(crate) mod names;
pub(crate) mod prompt_syntax;
mod prompt_template;
mod recipes;
pub(crate) mod sampling;
mod vae_tiling;

pub use gen::{read_images, GenSettings, GuideInputs};
pub use ip_scale::{IpBlock, IpMode, IpScale};
pub(crate) use models::flagged;
pub use models::{check_control_settings, recorded_path};
pub use models::{ControlNetSettings, IpAdapterSettings, LoraSetting, ModelSettings};
pub use names::{control_depth_name, precision_name, schedule_name, schedule_records, RNG};
pub use prompt_syntax::{parse_attention, PromptSyntax};
pub use prompt_template::{splitmix64, CategorySlots, Chosen, Expansion, PromptTemplate, Wildcards};
pub use recipes::recipe_warnings;
pub use sampling::{Sampling, SizeConditioning, TextToImage};
pub use vae_tiling::VaeTilingSetting;
