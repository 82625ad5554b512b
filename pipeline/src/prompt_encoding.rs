//! SDXL prompt conditioning as diffusers' `encode_prompt` builds it: per prompt, both encoders'
//! penultimate hidden states side by side (CLIP-L first) and bigG's pooled projection.

use crate::error::{Error, Result};
use crate::sdxl::Sdxl;
use crate::text_to_image::TextToImage;

impl Sdxl {
    /// (context [B, tokens, width], pooled [B, pooled width]) for the batch [negative, positive]
    /// when `guided`, else [positive].
    pub(crate) fn conditioning(&self, job: &TextToImage, guided: bool) -> Result<(Vec<f32>, Vec<f32>)> {
        let zero_negative = job.negative_prompt.is_none() && self.force_zeros_for_empty_prompt;
        let mut prompts = Vec::new();
        if guided && !zero_negative {
            prompts.push(job.negative_prompt.as_deref().unwrap_or(""));
        }
        prompts.push(job.prompt.as_str());
        let encoded: Vec<_> = self
            .tokenizers
            .iter()
            .zip(&self.text_encoders)
            .map(|(tok, enc)| enc.encode(&prompts.iter().map(|p| tok.encode(p)).collect::<Vec<_>>()))
            .collect::<std::result::Result<_, _>>()?;
        let (first, second) = (&encoded[0], &encoded[1]);
        let pooled = second.pooled.clone().ok_or_else(|| Error::Config("text encoder 2 gave no pooled output".into()))?;
        let (w1, w2) = (self.text_encoders[0].config().hidden_size, self.text_encoders[1].config().hidden_size);
        let mut context: Vec<f32> = first.penultimate.chunks_exact(w1).zip(second.penultimate.chunks_exact(w2)).flat_map(|(a, b)| a.iter().chain(b).copied()).collect();
        let mut pooled = pooled;
        if guided && zero_negative {
            context.splice(0..0, std::iter::repeat_n(0.0, context.len()));
            pooled.splice(0..0, std::iter::repeat_n(0.0, pooled.len()));
        }
        Ok((context, pooled))
    }
}
