//! LoRA for vkdiff: kohya and diffusers/PEFT files, their modules mapped onto the device weights
//! of the loaded networks by name, merged in place on the device with GEMMs and unmerged exactly
//! from host copies of the original weights.
//!
//! ```ignore
//! let lora = LoraFile::open(path)?;
//! let mut merger = LoraMerger::new();
//! println!("{}", merger.apply(&Targets::sdxl(&unet, &clip_l, &big_g), &[(&lora, 0.7)])?);
//! // ... sample ...
//! merger.restore()?;
//! ```

mod component;
mod error;
mod format;
mod merge;
mod metadata;
mod names;

pub use component::Component;
pub use error::{Error, Result};
pub use format::{Address, LoraFile, Module};
pub use merge::{LoraMerger, LoraSummary, Summary};
pub use names::Targets;
