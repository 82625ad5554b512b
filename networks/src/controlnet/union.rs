//! ControlNet-Union (xinsir/controlnet-union-sdxl-1.0 and its ProMax file; diffusers'
//! `ControlNetUnionModel`): a plain ControlNet plus a control-type embedding added to the time
//! embedding and a fusion of several conditioning images into one hint. The extras are a few
//! vectors per image or per recording, so they stay on the host in f32.

use crate::controlnet::config::ControlNetConfig;
use crate::controlnet::controlnet_model::ControlNetModel;
use crate::error::{Error, Result};
use crate::weights::{Checkpoint, Weights};
use vkdiff_runtime::{Context, Tensor};

/// One control image given to a ControlNet: for a Union model with its control type (index into
/// task_embedding) and its scale inside the fusion.
pub struct UnionCondition<'a> {
    /// [B, H, W, 3] RGB in [0, 1], in the run precision.
    pub image: &'a Tensor,
    pub control_type: usize,
    pub scale: f32,
}

/// y = W·x + b with W [outputs, inputs] row-major.
struct HostLinear {
    weight: Vec<f32>,
    bias: Vec<f32>,
}

impl HostLinear {
    fn load(w: &Weights, name: &str, inputs: usize, outputs: usize) -> Result<HostLinear> {
        let w = w.sub(name);
        Ok(HostLinear { weight: w.host("weight", &[outputs, inputs])?, bias: w.host("bias", &[outputs])? })
    }

    fn apply(&self, x: &[f32]) -> Vec<f32> {
        let rows = self.weight.chunks_exact(x.len());
        rows.zip(&self.bias)
            .map(|(row, b)| (row.iter().zip(x).map(|(w, v)| f64::from(w * v)).sum::<f64>() + f64::from(*b)) as f32)
            .collect()
    }
}

/// nn.LayerNorm with its default eps.
struct HostLayerNorm {
    gamma: Vec<f32>,
    beta: Vec<f32>,
}

impl HostLayerNorm {
    fn load(w: &Weights, name: &str, width: usize) -> Result<HostLayerNorm> {
        let w = w.sub(name);
        Ok(HostLayerNorm { gamma: w.host("weight", &[width])?, beta: w.host("bias", &[width])? })
    }

    fn apply(&self, x: &[f32]) -> Vec<f32> {
        let n = x.len() as f64;
        let mean = x.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
        let var = x.iter().map(|&v| (f64::from(v) - mean).powi(2)).sum::<f64>() / n;
        let inv = 1.0 / (var + 1e-5).sqrt();
        let norm = x.iter().map(|&v| (f64::from(v) - mean) * inv);
        norm.zip(self.gamma.iter().zip(&self.beta)).map(|(v, (g, b))| (v * f64::from(*g)) as f32 + b).collect()
    }
}

/// The Union's extra weights.
pub(super) struct UnionExtras {
    /// [types, width] row-major.
    task_embedding: Vec<f32>,
    types: usize,
    ln_1: HostLayerNorm,
    /// The value rows of the attention's in_proj: the only ones the output depends on (see
    /// [`UnionExtras::alpha`]).
    value: HostLinear,
    out_proj: HostLinear,
    ln_2: HostLayerNorm,
    c_fc: HostLinear,
    c_proj: HostLinear,
    spatial: HostLinear,
    control_1: HostLinear,
    control_2: HostLinear,
    /// The sinusoid each control-type slot gets: (width, flip_sin_to_cos, freq_shift).
    sinusoid: (usize, bool, f32),
}

impl UnionExtras {
    /// The extras if the checkpoint has a `task_embedding` (or, for random weights, the config
    /// names `num_control_type`); its rows give the number of control types.
    pub(super) fn load(w: &Weights, ckpt: &Checkpoint, config: &ControlNetConfig) -> Result<Option<UnionExtras>> {
        let width = config.encoder.block_out_channels[0];
        let types = match (ckpt.stored_shape("task_embedding").as_deref(), config.control_types) {
            (None, None) => return Ok(None),
            (None, Some(named)) => named,
            (Some(&[rows, cols]), named) => {
                if cols != width {
                    return Err(Error::Checkpoint(format!(
                        "the ControlNet-Union's `task_embedding` is [{rows}, {cols}], but its tokens are {width} \
                         wide (the first block's width)"
                    )));
                }
                if let Some(named) = named.filter(|&n| n != rows) {
                    return Err(Error::Config(format!(
                        "the ControlNet-Union's config says num_control_type {named}, its `task_embedding` has \
                         {rows} rows"
                    )));
                }
                rows
            }
            (Some(other), _) => {
                return Err(Error::Checkpoint(format!(
                    "the ControlNet-Union's `task_embedding` has shape {other:?}, not [types, width]"
                )))
            }
        };
        let encoder = &config.encoder;
        let id_dim = encoder.addition_time_embed_dim.ok_or_else(|| {
            Error::Config("a ControlNet-Union needs `addition_time_embed_dim` (its control-type embedding)".into())
        })?;
        let layer = w.sub("transformer_layes.0");
        let attn = layer.sub("attn");
        // ComfyUI saves nn.MultiheadAttention's fused projection as a Linear `in_proj`.
        let in_proj = if attn.has("in_proj_weight") {
            HostLinear {
                weight: attn.host("in_proj_weight", &[3 * width, width])?,
                bias: attn.host("in_proj_bias", &[3 * width])?,
            }
        } else {
            HostLinear::load(&attn, "in_proj", width, 3 * width)?
        };
        let value = HostLinear {
            weight: in_proj.weight[2 * width * width..].to_vec(),
            bias: in_proj.bias[2 * width..].to_vec(),
        };
        let time = encoder.time_embed_dim();
        Ok(Some(UnionExtras {
            task_embedding: w.host("task_embedding", &[types, width])?,
            types,
            ln_1: HostLayerNorm::load(&layer, "ln_1", width)?,
            value,
            out_proj: HostLinear::load(&attn, "out_proj", width, width)?,
            ln_2: HostLayerNorm::load(&layer, "ln_2", width)?,
            c_fc: HostLinear::load(&layer, "mlp.c_fc", width, 4 * width)?,
            c_proj: HostLinear::load(&layer, "mlp.c_proj", 4 * width, width)?,
            spatial: HostLinear::load(w, "spatial_ch_projs", width, width)?,
            control_1: HostLinear::load(w, "control_add_embedding.linear_1", id_dim * types, time)?,
            control_2: HostLinear::load(w, "control_add_embedding.linear_2", time, time)?,
            sinusoid: (id_dim, encoder.flip_sin_to_cos, encoder.freq_shift),
        }))
    }

    /// The per-channel bias one condition's token adds to its hint. diffusers feeds its
    /// nn.MultiheadAttention [B, T, C] with batch_first=False, so it attends across the batch
    /// rows at each token position; this is that attention for a batch whose rows are alike
    /// (softmax uniform, so the output is out_proj(value(ln_1(x)))): exact whenever every row
    /// carries the same images (one image with its CFG halves), and ComfyUI's result always.
    /// One image never depends on its batch-mates here.
    fn alpha(&self, token: &[f32]) -> Vec<f32> {
        let attended = self.out_proj.apply(&self.value.apply(&self.ln_1.apply(token)));
        let x: Vec<f32> = token.iter().zip(&attended).map(|(a, b)| a + b).collect();
        let mut hidden = self.c_fc.apply(&self.ln_2.apply(&x));
        for v in &mut hidden {
            *v /= 1.0 + (-1.702 * *v).exp(); // QuickGELU
        }
        let x: Vec<f32> = x.iter().zip(self.c_proj.apply(&hidden)).map(|(a, b)| a + b).collect();
        self.spatial.apply(&x)
    }

    /// control_add_embedding(sinusoid of each slot of the multi-hot `types`) [time width].
    fn control_embedding(&self, types: &[usize]) -> Vec<f32> {
        let (dim, flip, shift) = self.sinusoid;
        let half = dim / 2;
        let mut x = Vec::with_capacity(dim * self.types);
        for t in 0..self.types {
            let v = if types.contains(&t) { 1.0f32 } else { 0.0 };
            let args: Vec<f32> =
                (0..half).map(|k| v * (-(10000f32.ln()) * k as f32 / (half as f32 - shift)).exp()).collect();
            let (sin, cos) = (args.iter().map(|a| a.sin()), args.iter().map(|a| a.cos()));
            if flip {
                x.extend(cos.chain(sin));
            } else {
                x.extend(sin.chain(cos));
            }
        }
        let mut h = self.control_1.apply(&x);
        for v in &mut h {
            *v /= 1.0 + (-*v).exp(); // SiLU
        }
        self.control_2.apply(&h)
    }
}

impl ControlNetModel {
    /// Some(N) for a ControlNet-Union model (its number of control types), None for a plain
    /// ControlNet.
    pub fn control_types(&self) -> Option<usize> {
        self.union.as_ref().map(|u| u.types)
    }

    /// Union: hint = Σ_j scale_j · (c_j + alpha_j), c_j = cond_embedding(image_j), alpha_j from
    /// the token scale_j · (mean_hw(c_j) + task_embedding[type_j]), into `out` (same shape rules as
    /// [`ControlNetModel::encode_condition_into`]). diffusers' rule for the scales: one condition
    /// gets scale 1 here and the residuals × its scale ([`super::ControlNetInputs::scale`]);
    /// two or more in one net get their scales here and residuals × 1. A plain ControlNet takes
    /// exactly one condition of scale 1 (its control type unused): encode_condition_into.
    pub fn encode_conditions_into(&self, conditions: &[UnionCondition], out: &Tensor) -> Result<()> {
        let Some(first) = conditions.first() else {
            return Err(Error::Config("no conditioning image given to the ControlNet".into()));
        };
        let Some(union) = &self.union else {
            if conditions.len() != 1 || first.scale != 1.0 {
                return Err(Error::Config(format!(
                    "a plain ControlNet takes one conditioning image of scale 1, not {} (scale {}); several \
                     control types in one net need a ControlNet-Union",
                    conditions.len(),
                    first.scale
                )));
            }
            return self.encode_condition_into(first.image, out);
        };
        for c in conditions {
            if c.image.shape() != first.image.shape() {
                return Err(Error::Config(format!(
                    "ControlNet-Union conditioning images differ in shape: {:?} and {:?}",
                    first.image.shape(),
                    c.image.shape()
                )));
            }
            if c.control_type >= union.types {
                return Err(Error::Config(format!(
                    "control type {} is out of range: this ControlNet-Union has {} (0..{})",
                    c.control_type,
                    union.types,
                    union.types - 1
                )));
            }
        }
        let [_, h, w, c] = self.check_hint_tensor(first.image.shape(), out)?;
        let pixels = h * w;
        let hint = out.context().zeros(out.shape(), out.dtype())?;
        let mut sum = vec![0f32; out.numel()];
        for cond in conditions {
            self.encode_condition_into(cond.image, &hint)?;
            let values = hint.download()?;
            for (row, total) in values.chunks_exact(pixels * c).zip(sum.chunks_exact_mut(pixels * c)) {
                let mut mean = vec![0f64; c];
                for px in row.chunks_exact(c) {
                    mean.iter_mut().zip(px).for_each(|(m, v)| *m += f64::from(*v));
                }
                let task = &union.task_embedding[cond.control_type * c..][..c];
                let token: Vec<f32> =
                    mean.iter().zip(task).map(|(m, t)| cond.scale * ((*m / pixels as f64) as f32 + t)).collect();
                let alpha = union.alpha(&token);
                for (px, out_px) in row.chunks_exact(c).zip(total.chunks_exact_mut(c)) {
                    for ((o, v), a) in out_px.iter_mut().zip(px).zip(&alpha) {
                        *o += cond.scale * (v + a);
                    }
                }
            }
        }
        Ok(out.write(&sum)?)
    }

    /// The control embedding of `types` for `rows` batch rows, to be added to the time embedding
    /// (None for a plain ControlNet, which takes no control types).
    pub(super) fn control_embedding(&self, ctx: &Context, types: &[usize], rows: usize) -> Result<Option<Tensor>> {
        let union = match (&self.union, types) {
            (None, []) => return Ok(None),
            (None, _) => return Err(Error::Config("a plain ControlNet takes no control types".into())),
            (Some(u), []) => {
                return Err(Error::Config(format!(
                    "a ControlNet-Union needs its active control types (0..{}) in ControlNetInputs::control_types",
                    u.types
                )))
            }
            (Some(u), _) => u,
        };
        if let Some(&bad) = types.iter().find(|&&t| t >= union.types) {
            return Err(Error::Config(format!(
                "control type {bad} is out of range: this ControlNet-Union has {} (0..{})",
                union.types,
                union.types - 1
            )));
        }
        let emb = union.control_embedding(types);
        let width = emb.len();
        let repeated: Vec<f32> = emb.iter().copied().cycle().take(rows * width).collect();
        Ok(Some(ctx.upload(&[rows, width], self.dtype, &repeated)?))
    }
}
