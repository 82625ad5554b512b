//! SDXL prompt conditioning as diffusers' `encode_prompt` builds it: per prompt, both encoders'
//! penultimate hidden states side by side (CLIP-L first) and bigG's pooled projection.

use crate::error::{finite, Error, Result};
use crate::sdxl::Sdxl;
use crate::settings::prompt_syntax::PromptSyntax;
use crate::tokenizer::CONTEXT;
use vkdiff_setting::Message;

/// One prompt's conditioning for the UNet, rows [negative, positive] with guidance, else
/// [positive].
#[derive(Clone, Debug)]
pub struct Conditioning {
    /// [rows, tokens, cross_attention_dim], row-major.
    pub context: Vec<f32>,
    /// Tokens per row: 77, or any number with [`crate::PromptSyntax::Weighted`].
    pub tokens: usize,
    /// [rows, pooled width].
    pub pooled: Vec<f32>,
}

impl Sdxl {
    /// The prompt's conditioning as `syntax` reads it.
    pub fn encode_prompt_as(
        &self,
        syntax: PromptSyntax,
        prompt: &str,
        negative: Option<&str>,
        guided: bool,
    ) -> Result<Conditioning> {
        match syntax {
            PromptSyntax::Plain => self.encode_prompt(prompt, negative, guided),
            PromptSyntax::Weighted => self.encode_weighted_prompt(prompt, negative, guided),
        }
    }

    /// Tokens of `prompt` past the 75 that [`PromptSyntax::Plain`] reads (0 when it fits).
    pub fn tokens_cut(&self, prompt: &str) -> usize {
        self.tokenizers[0].tokens(prompt).len().saturating_sub(CONTEXT - 2)
    }

    /// One warning per plain prompt past CLIP's 75 tokens, which loses its end as in diffusers.
    pub fn cut_prompt_warnings<'a>(
        &self,
        syntax: PromptSyntax,
        prompts: impl Iterator<Item = &'a String>,
    ) -> Vec<String> {
        if syntax != PromptSyntax::Plain {
            return Vec::new();
        }
        prompts
            .filter_map(|prompt| {
                let cut = self.tokens_cut(prompt);
                (cut > 0).then(|| {
                    format!(
                        "warning: the last {cut} tokens of \"{prompt}\" are cut (CLIP reads 75); {} weighted reads any \
                        length",
                        Message::setting("prompt_syntax")
                    )
                })
            })
            .collect()
    }

    /// Encodes `prompt` (and `negative`, or zeros where the model asks for them when it is
    /// `None`) with both text encoders.
    pub fn encode_prompt(&self, prompt: &str, negative: Option<&str>, guided: bool) -> Result<Conditioning> {
        let zero_negative = negative.is_none() && self.force_zeros_for_empty_prompt;
        let mut prompts = Vec::new();
        if guided && !zero_negative {
            prompts.push(negative.unwrap_or(""));
        }
        prompts.push(prompt);
        let encoded: Vec<_> = self
            .tokenizers
            .iter()
            .zip(self.text_encoders()?)
            .map(|(tok, enc)| enc.encode(&prompts.iter().map(|p| tok.encode(p)).collect::<Vec<_>>()))
            .collect::<std::result::Result<_, _>>()?;
        let (first, second) = (&encoded[0], &encoded[1]);
        let pooled =
            second.pooled.as_deref().ok_or_else(|| Error::Config("text encoder 2 gave no pooled output".into()))?;
        let [w1, w2] = self.text_widths.0;
        let mut context: Vec<f32> = first
            .penultimate
            .chunks_exact(w1)
            .zip(second.penultimate.chunks_exact(w2))
            .flat_map(|(a, b)| a.iter().chain(b).copied())
            .collect();
        finite(&context, &|| "the text encoders' output".into())?;
        let mut pooled = finite(pooled, &|| "text encoder 2's pooled output".into())?.to_vec();
        if guided && zero_negative {
            context.splice(0..0, std::iter::repeat_n(0.0, context.len()));
            pooled.splice(0..0, std::iter::repeat_n(0.0, pooled.len()));
        }
        Ok(Conditioning { context, tokens: CONTEXT, pooled })
    }
}
