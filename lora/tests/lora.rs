//! vkdiff-lora against the tiny SDXL fixture: every file layout, merges checked against a CPU
//! reference in f32 and f16, exact restores, several LoRAs at once, and the error messages.

#[path = "lora/common.rs"]
#[allow(dead_code)]
mod common;
#[path = "lora/errors.rs"]
mod errors;
#[path = "lora/merge.rs"]
mod merge;
#[path = "lora/workflow.rs"]
mod workflow;
