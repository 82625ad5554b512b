//! The recording context networks are built in, and the layers with weights they are made of.

use crate::error::{Error, Result};
use crate::weights::Weights;
use vkdiff_runtime::ops::{self, ConvParams, Matmul, Padding};
use vkdiff_runtime::{Arena, Context, Dtype, Recorder, Recording, Tensor};

/// A network forward under construction: the recorder its dispatches go to and the arena its
/// intermediate tensors come from.
pub struct Graph {
    pub rec: Recorder,
    pub arena: Arena,
    pub dtype: Dtype,
    /// The projections of the conditioning (keys and values of the prompt's and the style
    /// images' tokens), recorded apart: they run once per conditioning, not once per evaluation.
    conditioning: Option<Recorder>,
}

impl Graph {
    pub fn new(ctx: &Context, dtype: Dtype) -> Result<Graph> {
        Ok(Graph { rec: Recorder::new(ctx, false)?, arena: Arena::new(ctx), dtype, conditioning: None })
    }

    /// A scratch tensor in the run precision.
    pub fn alloc(&self, shape: &[usize]) -> Result<Tensor> {
        Ok(self.arena.tensor(shape, self.dtype)?)
    }

    /// alpha·linear(x) of a conditioning input `x`, recorded among the conditioning's
    /// projections into a tensor of its own (not the arena's: the evaluation reads it every run).
    pub fn project_conditioning(&mut self, linear: &Linear, x: &Tensor, alpha: f32) -> Result<Tensor> {
        let ctx = self.rec.context().clone();
        let out = ctx.zeros(&with_last(x.shape(), linear.outputs()), self.dtype)?;
        let rec = match &mut self.conditioning {
            Some(rec) => rec,
            None => self.conditioning.insert(Recorder::new(&ctx, false)?),
        };
        linear.record_into(rec, x, &out, false, alpha)?;
        Ok(out)
    }

    /// Ends recording.
    pub fn finish(self) -> Result<Recorded> {
        Ok(Recorded {
            evaluation: self.rec.finish()?,
            conditioning: self.conditioning.map(Recorder::finish).transpose()?,
            _arena: self.arena,
        })
    }
}

/// A recorded evaluation, replayed for every evaluation, and the projections of its
/// conditioning, run after each change of the conditioning inputs.
pub struct Recorded {
    pub evaluation: Recording,
    conditioning: Option<Recording>,
    /// The intermediate tensors' buffers, owned by this recording alone.
    _arena: Arena,
}

impl Recorded {
    /// Projects the conditioning inputs as they are now; the evaluation reads the result.
    pub fn project_conditioning(&self) -> Result<()> {
        if let Some(rec) = &self.conditioning {
            rec.run()?;
        }
        Ok(())
    }
}

/// `shape` with its last dimension replaced.
pub fn with_last(shape: &[usize], last: usize) -> Vec<usize> {
    let mut s = shape.to_vec();
    *s.last_mut().unwrap() = last;
    s
}

/// PyTorch `Linear`: weight [out, in], optional bias.
pub struct Linear {
    pub weight: Tensor,
    pub bias: Option<Tensor>,
}

impl Linear {
    pub fn load(w: &Weights, name: &str, inputs: usize, outputs: usize, bias: bool) -> Result<Linear> {
        let w = w.sub(name);
        let weight = w.tensor("weight", &[outputs, inputs])?;
        let bias = if bias { Some(w.tensor("bias", &[outputs])?) } else { None };
        Ok(Linear { weight, bias })
    }

    pub fn outputs(&self) -> usize {
        self.weight.shape()[0]
    }

    /// x[.., in] → [.., out].
    pub fn forward(&self, g: &mut Graph, x: &Tensor) -> Result<Tensor> {
        let out = g.alloc(&with_last(x.shape(), self.outputs()))?;
        self.forward_into(g, x, &out, false, 1.0)?;
        Ok(out)
    }

    /// out = alpha·x·Wᵀ + bias (+ out when `accumulate`: a fused residual add).
    pub fn forward_into(&self, g: &mut Graph, x: &Tensor, out: &Tensor, accumulate: bool, alpha: f32) -> Result<()> {
        self.record_into(&mut g.rec, x, out, accumulate, alpha)
    }

    fn record_into(&self, rec: &mut Recorder, x: &Tensor, out: &Tensor, accumulate: bool, alpha: f32) -> Result<()> {
        let (n, k) = (self.weight.shape()[0], self.weight.shape()[1]);
        if x.shape().last() != Some(&k) {
            return Err(Error::Config(format!("linear layer takes {k} features, input is {:?}", x.shape())));
        }
        let mut spec = Matmul::dense(x.numel() / k, n, k, true);
        spec.accumulate = accumulate;
        spec.alpha = alpha;
        Ok(ops::matmul(rec, x, &self.weight, self.bias.as_ref(), out, &spec)?)
    }
}

/// PyTorch `Conv2d` (square kernel, bias), weights re-laid out for NHWC.
pub struct Conv2d {
    weight: Tensor,
    bias: Tensor,
    stride: usize,
    pad: Padding,
}

impl Conv2d {
    pub fn load(
        w: &Weights,
        name: &str,
        inputs: usize,
        outputs: usize,
        kernel: usize,
        stride: usize,
        pad: usize,
    ) -> Result<Conv2d> {
        let w = w.sub(name);
        Ok(Conv2d {
            weight: w.conv_weight("weight", [outputs, inputs, kernel, kernel])?,
            bias: w.tensor("bias", &[outputs])?,
            stride,
            pad: Padding::same(pad),
        })
    }

    /// The same convolution with other (asymmetric) padding.
    pub fn with_padding(self, pad: Padding) -> Conv2d {
        Conv2d { pad, ..self }
    }

    fn params(&self, accumulate: bool) -> ConvParams {
        ConvParams { stride: self.stride, pad: self.pad, accumulate, relu: false }
    }

    /// x[B, H, W, in] → [B, H', W', out].
    pub fn forward(&self, g: &mut Graph, x: &Tensor) -> Result<Tensor> {
        let [b, h, w, _] = [x.shape()[0], x.shape()[1], x.shape()[2], x.shape()[3]];
        let k = self.weight.shape()[1];
        let size = |n: usize, pads: usize| (n + pads - k) / self.stride + 1;
        let out = g.alloc(&[
            b,
            size(h, self.pad.top + self.pad.bottom),
            size(w, self.pad.left + self.pad.right),
            self.weight.shape()[0],
        ])?;
        self.forward_into(g, x, &out, false)?;
        Ok(out)
    }

    /// out (+)= conv(x); accumulating finishes a residual branch without a separate add.
    pub fn forward_into(&self, g: &mut Graph, x: &Tensor, out: &Tensor, accumulate: bool) -> Result<()> {
        Ok(ops::conv2d(&mut g.rec, x, &self.weight, Some(&self.bias), out, &self.params(accumulate))?)
    }
}

/// GroupNorm over channels-last activations, optionally fused with SiLU.
pub struct GroupNorm {
    gamma: Tensor,
    beta: Tensor,
    groups: usize,
    eps: f32,
}

impl GroupNorm {
    pub fn load(w: &Weights, name: &str, channels: usize, groups: usize, eps: f32) -> Result<GroupNorm> {
        let w = w.sub(name);
        Ok(GroupNorm { gamma: w.tensor("weight", &[channels])?, beta: w.tensor("bias", &[channels])?, groups, eps })
    }

    pub fn forward(&self, g: &mut Graph, x: &Tensor, silu: bool) -> Result<Tensor> {
        let out = g.alloc(x.shape())?;
        ops::group_norm(&mut g.rec, x, &self.gamma, &self.beta, &out, self.groups, self.eps, silu)?;
        Ok(out)
    }
}

/// LayerNorm over the last dimension.
pub struct LayerNorm {
    gamma: Tensor,
    beta: Tensor,
    eps: f32,
}

impl LayerNorm {
    pub fn load(w: &Weights, name: &str, channels: usize, eps: f32) -> Result<LayerNorm> {
        let w = w.sub(name);
        Ok(LayerNorm { gamma: w.tensor("weight", &[channels])?, beta: w.tensor("bias", &[channels])?, eps })
    }

    pub fn forward(&self, g: &mut Graph, x: &Tensor) -> Result<Tensor> {
        let out = g.alloc(x.shape())?;
        ops::layer_norm(&mut g.rec, x, &self.gamma, &self.beta, &out, self.eps)?;
        Ok(out)
    }
}
