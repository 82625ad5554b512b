//! The UNet's conditioning vector: sinusoidal timestep embedding through `time_embedding`, plus
//! SDXL's `text_time` added conditioning (pooled text embeds and six size/crop ids).

use crate::error::{Error, Result};
use crate::layers::nn::{Graph, Linear};
use crate::unet::config::UNetConfig;
use crate::weights::Weights;
use vkdiff_runtime::ops::{self, TimestepEmbedding, UnaryOp};
use vkdiff_runtime::Tensor;

/// Linear → SiLU → Linear, as diffusers' `TimestepEmbedding`.
struct Mlp {
    linear_1: Linear,
    linear_2: Linear,
}

impl Mlp {
    fn load(w: &Weights, inputs: usize, width: usize) -> Result<Mlp> {
        Ok(Mlp {
            linear_1: Linear::load(w, "linear_1", inputs, width, true)?,
            linear_2: Linear::load(w, "linear_2", width, width, true)?,
        })
    }

    /// out (+)= linear_2(SiLU(linear_1(x))).
    fn forward_into(&self, g: &mut Graph, x: &Tensor, out: &Tensor, accumulate: bool) -> Result<()> {
        let h = self.linear_1.forward(g, x)?;
        ops::unary(&mut g.rec, UnaryOp::Silu, &h, &h, 1.0)?;
        self.linear_2.forward_into(g, &h, out, accumulate, 1.0)
    }
}

struct AddedTime {
    mlp: Mlp,
    id_dim: usize,
    text_dim: usize,
}

pub struct Embeddings {
    time: Mlp,
    sinusoid: TimestepEmbedding,
    added: Option<AddedTime>,
    width: usize,
}

impl Embeddings {
    pub fn load(w: &Weights, config: &UNetConfig) -> Result<Embeddings> {
        let c0 = config.block_out_channels[0];
        let width = config.time_embed_dim();
        let sinusoid = TimestepEmbedding {
            dim: c0,
            flip_sin_to_cos: config.flip_sin_to_cos,
            downscale_freq_shift: config.freq_shift,
            max_period: 10000.0,
            scale: 1.0,
        };
        let added = match (config.addition_time_embed_dim, config.projection_class_embeddings_input_dim) {
            (Some(id_dim), Some(input)) if config.addition_embed_type.is_some() => {
                let text_dim = input.checked_sub(6 * id_dim).ok_or_else(|| {
                    Error::Config(format!(
                        "projection_class_embeddings_input_dim {input} is smaller than six time ids of {id_dim}"
                    ))
                })?;
                Some(AddedTime { mlp: Mlp::load(&w.sub("add_embedding"), input, width)?, id_dim, text_dim })
            }
            _ => None,
        };
        Ok(Embeddings { time: Mlp::load(&w.sub("time_embedding"), c0, width)?, sinusoid, added, width })
    }

    /// Width of the pooled text embedding the added conditioning expects, if any.
    pub fn text_embeds_dim(&self) -> Option<usize> {
        self.added.as_ref().map(|a| a.text_dim)
    }

    /// SiLU(temb + aug_emb + extra) [B, width], what every resnet projects. `timesteps` [B] and
    /// `time_ids` [B, 6] are f32; `extra` [B, width] is a ControlNet-Union's control embedding.
    pub fn forward(
        &self,
        g: &mut Graph,
        timesteps: &Tensor,
        added: Option<(&Tensor, &Tensor)>,
        extra: Option<&Tensor>,
    ) -> Result<Tensor> {
        let b = timesteps.numel();
        let sinusoid = g.alloc(&[b, self.sinusoid.dim])?;
        ops::timestep_embedding(&mut g.rec, timesteps, &sinusoid, &self.sinusoid)?;
        let emb = g.alloc(&[b, self.width])?;
        self.time.forward_into(g, &sinusoid, &emb, false)?;
        match (&self.added, added) {
            (Some(a), Some((text_embeds, time_ids))) => {
                let e = TimestepEmbedding { dim: a.id_dim, ..self.sinusoid };
                let ids = g.alloc(&[b * 6, a.id_dim])?;
                ops::timestep_embedding(&mut g.rec, time_ids, &ids, &e)?;
                let joined = g.alloc(&[b, a.text_dim + 6 * a.id_dim])?;
                ops::concat_channels(&mut g.rec, text_embeds, &ids.reshape(&[b, 6 * a.id_dim])?, &joined)?;
                a.mlp.forward_into(g, &joined, &emb, true)?;
            }
            (Some(_), None) => {
                return Err(Error::Config("this UNet needs text_embeds and time_ids (SDXL added conditioning)".into()))
            }
            (None, _) => {}
        }
        if let Some(extra) = extra {
            if extra.shape() != [b, self.width] {
                return Err(Error::Config(format!(
                    "an extra embedding of shape {:?} cannot join the time embedding [{b}, {}]",
                    extra.shape(),
                    self.width
                )));
            }
            ops::add(&mut g.rec, &emb, extra, &emb)?;
        }
        ops::unary(&mut g.rec, UnaryOp::Silu, &emb, &emb, 1.0)?;
        Ok(emb)
    }
}
