//! vkdiff-lora against the tiny SDXL fixture: every file layout, merges checked against a CPU
//! reference in f32 and f16, exact restores, several LoRAs at once, and the error messages.

mod common;
mod errors;
mod merge;
mod workflow;
