//! diffusers `ResnetBlock2D` (time embedding added, not FiLM; none in the VAE) and the resamplers.

use crate::error::Result;
use crate::layers::nn::{Conv2d, Graph, GroupNorm, Linear};
use crate::weights::Weights;
use vkdiff_runtime::ops::{self, Padding};
use vkdiff_runtime::Tensor;

pub struct ResnetBlock2D {
    norm1: GroupNorm,
    conv1: Conv2d,
    time_emb_proj: Option<Linear>,
    norm2: GroupNorm,
    conv2: Conv2d,
    conv_shortcut: Option<Conv2d>,
}

/// Norm settings shared by every resnet of a network.
#[derive(Clone, Copy)]
pub struct NormSpec {
    pub groups: usize,
    pub eps: f32,
}

impl ResnetBlock2D {
    pub fn load(
        w: &Weights,
        inputs: usize,
        outputs: usize,
        temb: Option<usize>,
        norm: NormSpec,
    ) -> Result<ResnetBlock2D> {
        let conv_shortcut =
            if inputs != outputs { Some(Conv2d::load(w, "conv_shortcut", inputs, outputs, 1, 1, 0)?) } else { None };
        Ok(ResnetBlock2D {
            norm1: GroupNorm::load(w, "norm1", inputs, norm.groups, norm.eps)?,
            conv1: Conv2d::load(w, "conv1", inputs, outputs, 3, 1, 1)?,
            time_emb_proj: temb.map(|t| Linear::load(w, "time_emb_proj", t, outputs, true)).transpose()?,
            norm2: GroupNorm::load(w, "norm2", outputs, norm.groups, norm.eps)?,
            conv2: Conv2d::load(w, "conv2", outputs, outputs, 3, 1, 1)?,
            conv_shortcut,
        })
    }

    /// x[B, H, W, in], `emb_silu` = SiLU(time embedding) [B, temb] → [B, H, W, out].
    pub fn forward(&self, g: &mut Graph, x: &Tensor, emb_silu: Option<&Tensor>) -> Result<Tensor> {
        let h = self.norm1.forward(g, x, true)?;
        let h = self.conv1.forward(g, &h)?;
        if let (Some(proj), Some(emb)) = (&self.time_emb_proj, emb_silu) {
            let t = proj.forward(g, emb)?;
            let c = t.shape()[1];
            ops::add(&mut g.rec, &h, &t.reshape(&[t.shape()[0], 1, 1, c])?, &h)?;
        }
        let h = self.norm2.forward(g, &h, true)?;
        let out = match &self.conv_shortcut {
            Some(shortcut) => shortcut.forward(g, x)?,
            None => {
                let out = g.alloc(x.shape())?;
                ops::unary(&mut g.rec, ops::UnaryOp::Scale, x, &out, 1.0)?;
                out
            }
        };
        self.conv2.forward_into(g, &h, &out, true)?;
        Ok(out)
    }
}

/// `Downsample2D`: 3×3 convolution, stride 2, padding 1; with padding 0 (the VAE) diffusers
/// pads only the bottom and right by one.
pub struct Downsample2D(Conv2d);

impl Downsample2D {
    pub fn load(w: &Weights, channels: usize, padding: usize) -> Result<Downsample2D> {
        let pad = if padding == 0 { Padding { top: 0, left: 0, bottom: 1, right: 1 } } else { Padding::same(padding) };
        Ok(Downsample2D(Conv2d::load(w, "conv", channels, channels, 3, 2, 0)?.with_padding(pad)))
    }

    pub fn forward(&self, g: &mut Graph, x: &Tensor) -> Result<Tensor> {
        self.0.forward(g, x)
    }
}

/// `Upsample2D`: nearest-neighbour 2×, then a 3×3 convolution.
pub struct Upsample2D(Conv2d);

impl Upsample2D {
    pub fn load(w: &Weights, channels: usize) -> Result<Upsample2D> {
        Ok(Upsample2D(Conv2d::load(w, "conv", channels, channels, 3, 1, 1)?))
    }

    pub fn forward(&self, g: &mut Graph, x: &Tensor) -> Result<Tensor> {
        let s = x.shape();
        let up = g.alloc(&[s[0], 2 * s[1], 2 * s[2], s[3]])?;
        ops::upsample_nearest2x(&mut g.rec, x, &up)?;
        self.0.forward(g, &up)
    }
}
