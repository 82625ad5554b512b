//! Prompts in A1111's emphasis syntax, of any length, encoded as diffusers' long-prompt-weighting
//! SDXL pipeline does (`examples/community/lpw_stable_diffusion_xl.py`,
//! `get_weighted_text_embeddings_sdxl`): `(word)` ×1.1, `[word]` ÷1.1, `(word:1.3)` ×1.3, nested
//! ones multiplied, `\(` for a literal bracket; the tokens cut into chunks of 75, each encoded
//! between BOS and EOS (the last chunk as long as it is, not padded to 77); the shorter of the
//! prompt and the negative padded with EOS to the other's length; each token's features moved
//! away from its chunk's last (EOS) features by its weight (as float16); the pooled output is the
//! last chunk's. ComfyUI differs: it pads every chunk to 77, weighs against the empty prompt's
//! features, takes the first chunk's pooled output, and repeats the shorter of prompt and
//! negative instead of padding it.

use crate::error::{Error, Result};
use crate::sdxl::prompt_encoding::Conditioning;
use crate::sdxl::Sdxl;
use crate::settings::prompt_syntax::parse_attention;
use half::f16;

/// Tokens per chunk between BOS and EOS.
const CHUNK: usize = 75;

/// One prompt's tokens for both tokenizers, and each token's weight.
struct Weighted {
    tokens: [Vec<u32>; 2],
    weights: Vec<f64>,
}

impl Sdxl {
    fn weighted_tokens(&self, prompt: &str) -> Result<Weighted> {
        let mut out = Weighted { tokens: [Vec::new(), Vec::new()], weights: Vec::new() };
        for (text, weight) in parse_attention(prompt)? {
            let ids = [self.tokenizers[0].tokens(&text), self.tokenizers[1].tokens(&text)];
            out.weights.extend(std::iter::repeat_n(weight, ids[0].len()));
            for (all, ids) in out.tokens.iter_mut().zip(ids) {
                all.extend(ids);
            }
        }
        if out.tokens[0].len() != out.tokens[1].len() {
            return Err(Error::Config("prompt: the two tokenizers cut it into different numbers of tokens".into()));
        }
        Ok(out)
    }

    /// [`Sdxl::encode_prompt`] for [`PromptSyntax::Weighted`]: rows [negative, positive] with
    /// guidance (an absent negative is `""`), else [positive]; any number of tokens.
    pub fn encode_weighted_prompt(&self, prompt: &str, negative: Option<&str>, guided: bool) -> Result<Conditioning> {
        let mut positive = self.weighted_tokens(prompt)?;
        let mut rows = vec![];
        if guided {
            let mut negative = self.weighted_tokens(negative.unwrap_or(""))?;
            // Padded with tokenizer 1's EOS, for both tokenizers, as diffusers' pipeline does.
            let eos = self.tokenizers[0].eos_id();
            let longest = positive.weights.len().max(negative.weights.len());
            for w in [&mut positive, &mut negative] {
                for t in &mut w.tokens {
                    t.resize(longest, eos);
                }
                w.weights.resize(longest, 1.0);
            }
            rows.push(negative);
        }
        rows.push(positive);
        if rows[0].weights.is_empty() {
            return Err(Error::Config("prompt: an empty prompt (and negative) has no tokens to encode".into()));
        }
        let mut context = Vec::new();
        let mut pooled = Vec::new();
        for row in &rows {
            let (c, p) = self.encode_chunks(row)?;
            context.extend(c);
            pooled.extend(p);
        }
        // BOS and EOS around every chunk.
        let tokens = rows[0].weights.len() + 2 * rows[0].weights.len().div_ceil(CHUNK);
        Ok(Conditioning { context, tokens, pooled })
    }

    /// One row: its chunks' weighted features side by side, and the last chunk's pooled output.
    fn encode_chunks(&self, row: &Weighted) -> Result<(Vec<f32>, Vec<f32>)> {
        let [w1, w2] = self.text_widths.0;
        let width = w1 + w2;
        let (mut context, mut pooled) = (Vec::new(), Vec::new());
        for start in (0..row.weights.len()).step_by(CHUNK) {
            let end = (start + CHUNK).min(row.weights.len());
            let ids: Vec<Vec<u32>> = (0..2)
                .map(|i| {
                    let tok = &self.tokenizers[i];
                    std::iter::once(tok.bos_id())
                        .chain(row.tokens[i][start..end].iter().copied())
                        .chain([tok.eos_id()])
                        .collect()
                })
                .collect();
            let [first, second] = self.text_encoders()?;
            let first = first.encode(std::slice::from_ref(&ids[0]))?;
            let second = second.encode(std::slice::from_ref(&ids[1]))?;
            let mut chunk: Vec<f32> = first
                .penultimate
                .chunks_exact(w1)
                .zip(second.penultimate.chunks_exact(w2))
                .flat_map(|(a, b)| a.iter().chain(b).copied())
                .collect();
            let tokens = ids[0].len();
            let last = chunk[(tokens - 1) * width..].to_vec();
            for (j, &weight) in row.weights[start..end].iter().enumerate() {
                // The chunk's weights are float16 there; BOS and EOS keep 1.
                let w = f16::from_f64(weight).to_f32();
                if w != 1.0 {
                    let features = &mut chunk[(j + 1) * width..(j + 2) * width];
                    for (f, l) in features.iter_mut().zip(&last) {
                        *f = l + (*f - l) * w;
                    }
                }
            }
            context.extend(chunk);
            pooled = second.pooled.ok_or_else(|| Error::Config("text encoder 2 gave no pooled output".into()))?;
        }
        crate::error::finite(&context, &|| "the text encoders' output".into())?;
        Ok((context, pooled))
    }
}
