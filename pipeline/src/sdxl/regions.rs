//! A prompt per region and a strength per region, as ComfyUI does them:
//! - masked conditioning (`calc_cond_batch`): the UNet runs once more per region prompt, and the
//!   positive prediction is each prompt's, weighted by its mask on the latent grid and normalised
//!   where masks overlap, before classifier-free guidance;
//! - differential denoising (`DifferentialDiffusion` in `KSamplerX0Inpaint`): at each step a pixel
//!   whose strength is below the step's threshold is held on the init latent's noised path.

use crate::error::{Error, Result};
use crate::schedulers::PredictionType;
use crate::sdxl::prompt_encoding::Conditioning;

/// One image's region prompts. The scene's prompt is the image's own conditioning.
pub struct Regions<'a> {
    /// Each region prompt's conditioning, positive rows only (encoded without guidance).
    pub texts: &'a [Conditioning],
    /// On the latent grid (h × w, row-major): the scene prompt's mask, then each region's.
    pub masks: Vec<Vec<f32>>,
}

impl Regions<'_> {
    /// Every row of the image's text conditioning (`rows` of its own, then one per region) and of
    /// its pooled embeddings; all must have the recorded number of tokens.
    pub(crate) fn rows(
        own: &Conditioning,
        regions: Option<&Regions<'_>>,
        count: usize,
    ) -> Result<(Vec<f32>, Vec<f32>)> {
        let texts: &[Conditioning] = regions.map_or(&[], |r| r.texts);
        if texts.len() != count || regions.is_some_and(|r| r.masks.len() != count + 1) {
            return Err(Error::Config(format!(
                "an image of the batch has {} region prompts and {} masks for a pass recorded for {count}",
                texts.len(),
                regions.map_or(0, |r| r.masks.len())
            )));
        }
        let (mut context, mut pooled) = (own.context.clone(), own.pooled.clone());
        for text in texts {
            if text.tokens != own.tokens {
                return Err(Error::Config(format!(
                    "a region prompt of {} tokens beside a prompt of {}: give prompts of one length",
                    text.tokens, own.tokens
                )));
            }
            context.extend_from_slice(&text.context);
            pooled.extend_from_slice(&text.pooled);
        }
        Ok((context, pooled))
    }
}

/// `calc_cond_batch` over one image's positive predictions (NHWC, `channels` per pixel): each
/// weighted by its mask, summed in order, over 1e-37 plus the masks' sum.
pub(crate) fn blend(predictions: &[&[f32]], masks: &[Vec<f32>], channels: usize) -> Vec<f32> {
    let n = predictions[0].len();
    let mut total = vec![0.0f32; n];
    let mut count = vec![1e-37f32; n];
    for (prediction, mask) in predictions.iter().zip(masks) {
        for (j, (t, c)) in total.iter_mut().zip(count.iter_mut()).enumerate() {
            let m = mask[j / channels];
            *t += prediction[j] * m;
            *c += m;
        }
    }
    total.iter().zip(&count).map(|(t, c)| t / c).collect()
}

/// How far below a step's threshold a relative strength may fall and still reach it: far above
/// the rounding of feathering (1e-16), far below any strength anyone gives (two decimals).
pub const STRENGTH_TOLERANCE: f64 = 1e-9;

/// One image's strength per latent pixel, over the largest strength of the run (which is the
/// schedule's img2img strength), and what it starts from.
pub struct HeldLatents<'a> {
    /// On the latent grid (h × w), in [0, 1].
    pub relative: &'a [f64],
    /// The init latent (scaled sample) and the noise it was noised with, NCHW.
    pub x0: Vec<f32>,
    pub noise: Vec<f32>,
}

impl HeldLatents<'_> {
    /// The pixels held at a step of timestep `t` in a schedule starting at `t_from`:
    /// `DifferentialDiffusion`'s threshold (t − t_to) / (t_from − t_to), t_to = 0 (sigma_min's).
    /// A strength within [`STRENGTH_TOLERANCE`] of the threshold reaches it, so that a feathered
    /// field of one strength (1 up to rounding) is denoised from the first step.
    pub fn held(&self, t: f32, t_from: f32) -> Option<Vec<bool>> {
        let threshold = t as f64 / t_from as f64;
        let held: Vec<bool> = self.relative.iter().map(|&s| s + STRENGTH_TOLERANCE < threshold).collect();
        held.iter().any(|&h| h).then_some(held)
    }

    /// Held pixels of `x` (NCHW) take `noised`, the init latent at this step's level.
    pub fn hold_input(held: &[bool], x: &mut [f32], noised: &[f32]) {
        let plane = held.len();
        for (j, v) in x.iter_mut().enumerate() {
            if held[j % plane] {
                *v = noised[j];
            }
        }
    }

    /// Held pixels of the model's output (NCHW) predict the init latent: the noise for an
    /// epsilon model, the latent itself for one that predicts the sample.
    pub fn hold_output(&self, held: &[bool], prediction: PredictionType, output: &mut [f32]) -> Result<()> {
        let target = match prediction {
            PredictionType::Epsilon => &self.noise,
            PredictionType::Sample => &self.x0,
            PredictionType::V => {
                return Err(Error::Config(
                    "a strength per region needs an epsilon- or sample-predicting model, not v-prediction".into(),
                ))
            }
        };
        let plane = held.len();
        for (j, v) in output.iter_mut().enumerate() {
            if held[j % plane] {
                *v = target[j];
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_mask_covering_everything_gives_its_prediction_unchanged() {
        let a = [0.25f32, -3.5, 7.0, 1e-3];
        let b = [9.0f32, 9.0, 9.0, 9.0];
        let out = blend(&[&b, &a], &[vec![0.0, 0.0], vec![1.0, 1.0]], 2);
        assert_eq!(out, a);
        let half = blend(&[&b, &a], &[vec![0.5, 0.5], vec![0.5, 0.5]], 2);
        assert!(half.iter().zip(a.iter().zip(&b)).all(|(h, (x, y))| (h - (x + y) / 2.0).abs() < 1e-6));
    }
}
