//! What drives vkdiff's networks: the CLIP tokenizer, torch-compatible noise, the diffusers
//! schedulers, image inputs, the settings of a generation, SDXL with its guides and text-to-image
//! (`vkdiff gen`; `vkdiff-dataset` builds the dataset on it).

mod error;
pub mod files;
mod gen_job;
pub mod images;
mod rng;
mod schedulers;
mod sdxl;
mod settings;
mod tokenizer;

pub use error::{Error, Result};
pub use gen_job::{GenEvent, GenJob, GenRequest};
pub use rng::TorchCpuRng;
pub use schedulers::{
    PredictionType, Sampler, SamplerKind, ScheduleOptions, SchedulerConfig, TimestepSpacing, SDXL_SCHEDULER_CONFIG,
    TCD_DEFAULT_ETA,
};
pub use sdxl::{
    check_control_shape, BatchOutput, Conditioning, ControlGuide, ControlNetUse, Denoised, Denoiser, Generated, Guides,
    ImageGuide, InitLatents, IpAdapterUse, ItemInputs, Regions, Sdxl, StyleModels, Swaps, Timings, VaePlan,
    WorkflowModels,
};
pub use settings::{
    check_control_settings, control_depth_name, parse_attention, precision_name, read_images, recipe_warnings,
    recorded_path, schedule_name, schedule_records, ControlNetSettings, GenSettings, GuideInputs, IpAdapterSettings,
    IpBlock, IpMode, IpScale, LoraSetting, ModelSettings, PromptSyntax, Sampling, SizeConditioning, TextToImage,
    VaeTilingSetting, RNG,
};
pub use settings::{splitmix64, CategorySlots, Chosen, Expansion, PromptTemplate, Wildcards};
pub use tokenizer::ClipTokenizer;
pub use vkdiff_formats::RgbImage;
