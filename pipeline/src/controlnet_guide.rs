//! A depth ControlNet steering the denoising loop as `StableDiffusionXLControlNetPipeline` does:
//! the conditioning image resized to the output, run on both CFG halves, residuals scaled, and
//! switched off outside [start, end] of the steps.

use crate::error::{Error, Result};
use crate::images::control_tensor;
use crate::RgbImage;
use vkdiff_runtime::{Dtype, Tensor};
use vkdiff_unet::{nchw_to_nhwc, ControlNetInputs, ControlNetModel, ControlNetPass, ControlResiduals};

/// The `--controlnet` settings of one generation.
pub struct ControlGuide<'a> {
    pub net: &'a ControlNetModel,
    /// The conditioning image as given (a depth map already turned into an image).
    pub image: &'a RgbImage,
    /// `controlnet_conditioning_scale`.
    pub scale: f32,
    /// `control_guidance_start` / `_end`, fractions of the steps, compared in double precision
    /// as diffusers compares them.
    pub start: f64,
    pub end: f64,
}

/// The scale must be a number and the range a non-empty part of [0, 1].
pub fn check_control_settings(scale: f32, start: f64, end: f64) -> Result<()> {
    if !scale.is_finite() {
        return Err(Error::Config(format!("--control-scale {scale} is not a number")));
    }
    if !(0.0..=1.0).contains(&start) || !(0.0..=1.0).contains(&end) || start >= end {
        return Err(Error::Config(format!("--control-start {start} and --control-end {end} must satisfy 0 <= start < end <= 1")));
    }
    Ok(())
}

impl ControlGuide<'_> {
    /// Whether step `i` of `total` uses the ControlNet (diffusers' `controlnet_keep`).
    fn keeps(&self, i: usize, total: usize) -> bool {
        let (i, n) = (i as f64, total as f64);
        !(i / n < self.start || (i + 1.0) / n > self.end)
    }
}

/// A ControlNet recorded against the UNet's input tensors, ready for every step.
pub(crate) struct ControlRun<'a> {
    guide: &'a ControlGuide<'a>,
    pass: ControlNetPass,
    /// The encoded image the recording reads.
    _hint: Tensor,
}

/// The tensors the UNet and the ControlNet both read.
pub(crate) struct SharedInputs<'a> {
    pub sample: &'a Tensor,
    pub timesteps: &'a Tensor,
    pub context: &'a Tensor,
    pub added: (&'a Tensor, &'a Tensor),
}

impl<'a> ControlRun<'a> {
    /// Resizes and encodes the image for a `width`×`height` output and records the ControlNet.
    pub fn record(guide: &'a ControlGuide<'a>, inputs: &SharedInputs, width: usize, height: usize, dtype: Dtype) -> Result<ControlRun<'a>> {
        check_control_settings(guide.scale, guide.start, guide.end)?;
        let batch = inputs.sample.shape()[0];
        let (chw, shape) = control_tensor(guide.image, width, height);
        let hwc = nchw_to_nhwc(&chw, shape);
        let [_, c, h, w] = shape;
        let images: Vec<f32> = (0..batch).flat_map(|_| hwc.iter().copied()).collect();
        let ctx = inputs.sample.context();
        let image = ctx.upload(&[batch, h, w, c], dtype, &images)?;
        let hint = guide.net.encode_condition(&image)?;
        let pass = guide.net.record(&ControlNetInputs {
            sample: inputs.sample,
            timesteps: inputs.timesteps,
            encoder_hidden_states: inputs.context,
            added: Some(inputs.added),
            hint: &hint,
            scale: guide.scale,
        })?;
        Ok(ControlRun { guide, pass, _hint: hint })
    }

    pub fn residuals(&self) -> &ControlResiduals {
        &self.pass.residuals
    }

    /// Fills the residuals for step `i` of `total`: the ControlNet's, or zeros outside its range.
    pub fn step(&self, i: usize, total: usize) -> Result<()> {
        if self.guide.keeps(i, total) {
            return Ok(self.pass.run()?);
        }
        let r = &self.pass.residuals;
        for t in r.down.iter().chain([&r.mid]) {
            t.write(&vec![0.0; t.numel()])?;
        }
        Ok(())
    }
}
