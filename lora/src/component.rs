//! The networks of SDXL a LoRA adapts.

/// Which network a module adapts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Component {
    Unet,
    /// CLIP ViT-L (`lora_te1_`, `lora_te_`, `text_encoder.`).
    TextEncoder1,
    /// OpenCLIP bigG (`lora_te2_`, `text_encoder_2.`).
    TextEncoder2,
}
