//! ControlNets steering the denoising loop as `StableDiffusionXLControlNetPipeline` does: each
//! conditioning image resized to the output, run on both CFG halves, residuals scaled and switched
//! off outside the net's own [start, end] of the steps; several nets' residuals summed, as its
//! `MultiControlNetModel` sums them. A ControlNet-Union model sees one or more controls, as
//! `StableDiffusionXLControlNetUnionPipeline` gives them.

use crate::error::{Error, Result};
use crate::images::control_tensor;
use crate::settings::check_control_settings;
use crate::RgbImage;
use std::cell::{Cell, RefCell};
use vkdiff_networks::{
    nchw_to_nhwc, ControlNetInputs, ControlNetModel, ControlNetPass, ControlResiduals, UnionCondition,
};
use vkdiff_render::control::ControlKind;
use vkdiff_runtime::Tensor;
use vkdiff_setting::Message;

/// One `--controlnet` of one generation: the net, how it steers, and its images.
pub struct ControlGuide<'a> {
    pub use_: ControlNetUse<'a>,
    /// The conditioning images as given (a depth map already turned into an image), one per
    /// control the net sees.
    pub images: Vec<&'a RgbImage>,
}

/// A control image must have the image's shape: resized to another, it would be stretched and
/// no longer line up with the masks made from the same depth. Shapes that differ by less than
/// one `multiple` of the size (a rounding of the size, not a stretch) pass.
pub fn check_control_shape(
    setting: &str,
    control: &RgbImage,
    width: usize,
    height: usize,
    multiple: usize,
) -> Result<()> {
    let (cw, ch) = (control.width as f64, control.height as f64);
    let fitted_height = width as f64 * ch / cw;
    if (fitted_height - height as f64).abs() < multiple as f64 {
        return Ok(());
    }
    let suggested = ((fitted_height / multiple as f64).round() as usize).max(1) * multiple;
    Err(Error::Setting(
        Message::setting(setting)
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
    /// A ControlNet-Union model's control type of each image it sees (diffusers' `control_mode`);
    /// empty for a plain ControlNet, which sees one.
    pub control_types: &'a [usize],
    /// `controlnet_conditioning_scale`.
    pub scale: f32,
    /// `control_guidance_start` / `_end`, fractions of the steps, compared in double precision
    /// as diffusers compares them.
    pub start: f64,
    pub end: f64,
}

/// The ControlNet-Union type of a scene control: xinsir's order (0 openpose, 1 depth, 2 thick
/// lines, 3 thin lines: canny/lineart, 4 normal, 5 segment); the edges are 1-pixel lines.
pub fn union_control_type(kind: ControlKind) -> usize {
    match kind {
        ControlKind::Depth => 1,
        ControlKind::Edges => 3,
        ControlKind::Normals => 4,
        ControlKind::Segmentation => 5,
    }
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
    /// A Union model with two or more controls: the images, kept to be encoded again with the
    /// scales of each part of the steps, and whether the hint holds them on (Some(true)) or off.
    fused: RefCell<Vec<Tensor>>,
    fused_on: Cell<Option<bool>>,
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
        let fuses = use_.control_types.len() > 1;
        let pass = use_.net.record(&ControlNetInputs {
            sample: inputs.sample,
            timesteps: inputs.timesteps,
            encoder_hidden_states: inputs.context,
            added: Some(inputs.added),
            hint: &hint,
            // diffusers' ControlNetUnionModel scales each of several controls inside the net and
            // leaves its residuals as they come.
            scale: if fuses { 1.0 } else { use_.scale },
            add_to,
            control_types: use_.control_types,
        })?;
        Ok(ControlRun {
            use_,
            pass,
            hint,
            adds: add_to.is_some(),
            fused: RefCell::new(Vec::new()),
            fused_on: Cell::new(None),
        })
    }

    /// How many images the net sees: one per control of a Union model, else one.
    pub fn images_per_item(&self) -> usize {
        self.use_.control_types.len().max(1)
    }

    /// Encodes the conditioning images of every image of the batch (resized to `width`×`height`
    /// as diffusers does), each prepared once and given to its `rows_per_image` rows (negative,
    /// positive): every image's first row, then every image's second.
    pub fn set_images(
        &self,
        images: &[&[&RgbImage]],
        rows_per_image: usize,
        width: usize,
        height: usize,
    ) -> Result<()> {
        let tensors = (0..self.images_per_item())
            .map(|j| {
                let mut block = Vec::new();
                let mut size = [0; 4];
                for item in images {
                    let (chw, shape) = control_tensor(item[j], width, height);
                    block.extend(nchw_to_nhwc(&chw, shape));
                    size = shape;
                }
                let [_, c, h, w] = size;
                let rows = block.repeat(rows_per_image);
                Ok(self.hint.context().upload(&[images.len() * rows_per_image, h, w, c], self.hint.dtype(), &rows)?)
            })
            .collect::<Result<Vec<Tensor>>>()?;
        let net = self.use_.net;
        match self.use_.control_types {
            [] => net.encode_condition_into(&tensors[0], &self.hint)?,
            [control_type] => {
                let one = UnionCondition { image: &tensors[0], control_type: *control_type, scale: 1.0 };
                net.encode_conditions_into(&[one], &self.hint)?
            }
            _ => {
                *self.fused.borrow_mut() = tensors;
                self.fused_on.set(None);
            }
        }
        Ok(())
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
    /// ControlNet's step comes before the others'. A Union model with several controls runs at
    /// every step, as diffusers runs it: outside its range its controls' scales are 0 inside
    /// the net, and its residuals still count.
    pub fn step(&self, i: usize, total: usize) -> Result<()> {
        let on = self.use_.keeps(i, total);
        if self.use_.control_types.len() > 1 {
            self.encode_fused(on)?;
            return Ok(self.pass.run()?);
        }
        if on {
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

    /// The hint of several controls, each at the net's scale while `on`, else at 0.
    fn encode_fused(&self, on: bool) -> Result<()> {
        if self.fused_on.get() == Some(on) {
            return Ok(());
        }
        let scale = if on { self.use_.scale } else { 0.0 };
        let images = self.fused.borrow();
        let conditions: Vec<UnionCondition> = (images.iter().zip(self.use_.control_types))
            .map(|(image, &control_type)| UnionCondition { image, control_type, scale })
            .collect();
        self.use_.net.encode_conditions_into(&conditions, &self.hint)?;
        self.fused_on.set(Some(on));
        Ok(())
    }
}
