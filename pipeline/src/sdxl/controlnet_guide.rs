//! ControlNets steering the denoising loop as `StableDiffusionXLControlNetPipeline` does: each
//! conditioning image resized to the output, run on both CFG halves, residuals scaled and switched
//! off outside the net's own [start, end] of the steps; several nets' residuals summed, as its
//! `MultiControlNetModel` sums them.

use crate::error::{Error, Result};
use crate::images::control_tensor;
use crate::settings::check_control_settings;
use crate::RgbImage;
use vkdiff_networks::{nchw_to_nhwc, ControlNetInputs, ControlNetModel, ControlNetPass, ControlResiduals};
use vkdiff_runtime::Tensor;
use vkdiff_setting::Message;

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

/// A control image must have the image's shape: resized to another, it would be stretched and
/// no longer line up with the masks made from the same depth. Shapes that differ by less than
/// one `multiple` of the size (a rounding of the size, not a stretch) pass.
pub fn check_control_shape(control: &RgbImage, width: usize, height: usize, multiple: usize) -> Result<()> {
    let (cw, ch) = (control.width as f64, control.height as f64);
    let fitted_height = width as f64 * ch / cw;
    if (fitted_height - height as f64).abs() < multiple as f64 {
        return Ok(());
    }
    let suggested = ((fitted_height / multiple as f64).round() as usize).max(1) * multiple;
    Err(Error::Setting(
        Message::setting("depth")
            .then(format!(
                " is {}x{} and the image {width}x{height}: the control image would be stretched against its masks; \
                 give a size of its shape (",
                control.width, control.height
            ))
            .and("width")
            .then(format!(" {width} "))
            .and("height")
            .then(format!(" {suggested}) or cut the depth to the image's shape first (vkdiff scene "))
            .and("crops")
            .then(")"),
    ))
}

/// A ControlNet and how strongly, and when, it steers: what a batch of images shares.
#[derive(Clone, Copy)]
pub struct ControlNetUse<'a> {
    pub net: &'a ControlNetModel,
    pub scale: f32,
    pub start: f64,
    pub end: f64,
}

impl ControlNetUse<'_> {
    /// Whether step `i` of `total` uses the ControlNet (diffusers' `controlnet_keep`).
    fn keeps(&self, i: usize, total: usize) -> bool {
        let (i, n) = (i as f64, total as f64);
        !(i / n < self.start || (i + 1.0) / n > self.end)
    }
}

/// A ControlNet recorded against the UNet's input tensors, ready for every step of every batch:
/// new conditioning images are encoded into the hint tensor the recording reads.
pub(crate) struct ControlRun<'a> {
    use_: ControlNetUse<'a>,
    pass: ControlNetPass,
    /// [rows, h, w, C], the encoded images the recording reads.
    hint: Tensor,
    /// Whether it adds its residuals onto the first ControlNet's (a second net and after).
    adds: bool,
}

/// The tensors the UNet and the ControlNet both read.
pub(crate) struct SharedInputs<'a> {
    pub sample: &'a Tensor,
    pub timesteps: &'a Tensor,
    pub context: &'a Tensor,
    pub added: (&'a Tensor, &'a Tensor),
}

impl<'a> ControlRun<'a> {
    /// Records the ControlNet on `inputs`' shapes, with a hint tensor for their rows; with `add_to`,
    /// its residuals are added onto those (the first ControlNet's, which the UNet reads).
    pub fn record(
        use_: ControlNetUse<'a>,
        inputs: &SharedInputs,
        add_to: Option<&ControlResiduals>,
    ) -> Result<ControlRun<'a>> {
        check_control_settings(use_.scale, use_.start, use_.end)?;
        let s = inputs.sample.shape();
        let c0 = use_.net.config().encoder.block_out_channels[0];
        let hint = inputs.sample.context().zeros(&[s[0], s[1], s[2], c0], inputs.sample.dtype())?;
        let pass = use_.net.record(&ControlNetInputs {
            sample: inputs.sample,
            timesteps: inputs.timesteps,
            encoder_hidden_states: inputs.context,
            added: Some(inputs.added),
            hint: &hint,
            scale: use_.scale,
            control_types: &[],
            add_to,
        })?;
        Ok(ControlRun { use_, pass, hint, adds: add_to.is_some() })
    }

    /// Encodes one conditioning image per image of the batch (resized to `width`×`height` as
    /// diffusers does), each prepared once and given to its `rows_per_image` rows (negative,
    /// positive): every image's first row, then every image's second.
    pub fn set_images(&self, images: &[&RgbImage], rows_per_image: usize, width: usize, height: usize) -> Result<()> {
        let mut block = Vec::new();
        let mut size = [0; 4];
        for image in images {
            let (chw, shape) = control_tensor(image, width, height);
            block.extend(nchw_to_nhwc(&chw, shape));
            size = shape;
        }
        let [_, c, h, w] = size;
        let rows = block.repeat(rows_per_image);
        let tensor = self.hint.context().upload(&[images.len() * rows_per_image, h, w, c], self.hint.dtype(), &rows)?;
        Ok(self.use_.net.encode_condition_into(&tensor, &self.hint)?)
    }

    /// Projects the prompt's encoder hidden states as written now (see [`ControlNetPass`]).
    pub fn project_conditioning(&self) -> Result<()> {
        Ok(self.pass.project_conditioning()?)
    }

    pub fn residuals(&self) -> &ControlResiduals {
        &self.pass.residuals
    }

    /// Step `i` of `total`: the ControlNet's residuals, or nothing outside its range (zeros, for
    /// the first ControlNet, whose residuals the others add onto and the UNet reads). The first
    /// ControlNet's step comes before the others'.
    pub fn step(&self, i: usize, total: usize) -> Result<()> {
        if self.use_.keeps(i, total) {
            return Ok(self.pass.run()?);
        }
        if self.adds {
            return Ok(());
        }
        let r = &self.pass.residuals;
        for t in r.down.iter().chain([&r.mid]) {
            t.write(&vec![0.0; t.numel()])?;
        }
        Ok(())
    }
}
