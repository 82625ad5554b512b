//! diffusers `UNet2DConditionModel`, built from its config, recorded once per input shape into a
//! command buffer that is replayed for every evaluation.

use crate::error::{Error, Result};
use crate::layers::attention::CrossAttention;
use crate::layers::attention::IpAdapterInput;
use crate::layers::nn::{Conv2d, Graph, GroupNorm, Recorded};
use crate::unet::config::UNetConfig;
use crate::unet::down_path::{DownConditioning, DownOutput, DownPath};
use crate::unet::unet_2d_blocks::{BlockShape, Conditioning, MidBlock, UpBlock};
use crate::weights::Checkpoint;
use crate::weights::Parameters;
use vkdiff_runtime::ops;
use vkdiff_runtime::{Dtype, Tensor};

/// ControlNet's outputs, added where diffusers adds `down_block_additional_residuals` (onto each
/// skip tensor, [B, h, w, C] channels-last, in down-path order) and
/// `mid_block_additional_residual` (onto the mid block's output).
pub struct ControlResiduals {
    pub down: Vec<Tensor>,
    pub mid: Tensor,
}

/// One evaluation's inputs, all on the device. Activations are channels-last.
pub struct UNetInputs<'a> {
    /// [B, H, W, in_channels], run precision.
    pub sample: &'a Tensor,
    /// [B] f32 (discrete, possibly fractional, timesteps).
    pub timesteps: &'a Tensor,
    /// [B, tokens, cross_attention_dim], run precision.
    pub encoder_hidden_states: &'a Tensor,
    /// SDXL's added conditioning: pooled text embeds [B, E] (run precision) and time ids [B, 6] (f32).
    pub added: Option<(&'a Tensor, &'a Tensor)>,
    pub control: Option<&'a ControlResiduals>,
    pub ip: &'a [IpAdapterInput],
}

/// A recorded evaluation: write new values into the input tensors, after a change of
/// `encoder_hidden_states` or the image tokens [`UNetPass::project_conditioning`], then
/// [`UNetPass::run`] and read `output` ([B, H, W, out_channels]).
pub struct UNetPass {
    recorded: Recorded,
    pub output: Tensor,
}

impl UNetPass {
    /// Projects the conditioning inputs (prompt and image tokens) into every cross-attention's
    /// keys and values, which every later [`UNetPass::run`] reads.
    pub fn project_conditioning(&self) -> Result<()> {
        self.recorded.project_conditioning()
    }

    pub fn run(&self) -> Result<()> {
        Ok(self.recorded.evaluation.run()?)
    }

    /// Runs one evaluation and returns each dispatch's device time (recorded while the context
    /// was profiling: [`vkdiff_runtime::Context::set_profiling`]).
    pub fn run_profiled(&self) -> Result<Vec<vkdiff_runtime::Timing>> {
        Ok(self.recorded.evaluation.run_profiled()?)
    }

    /// The matrix-product arithmetic of one evaluation ([`vkdiff_runtime::Recording::flops`]).
    pub fn flops(&self) -> f64 {
        self.recorded.evaluation.flops()
    }

    /// Runs one evaluation and returns about how long each submission ran
    /// ([`vkdiff_runtime::Recording::run_submissions`]).
    pub fn run_submissions(&self) -> Result<Vec<std::time::Duration>> {
        Ok(self.recorded.evaluation.run_submissions()?)
    }
}

pub struct UNet {
    config: UNetConfig,
    dtype: Dtype,
    down: DownPath,
    mid: MidBlock,
    up: Vec<UpBlock>,
    norm_out: GroupNorm,
    conv_out: Conv2d,
    /// Every cross-attention, in diffusers' attention-processor order.
    crosses: Vec<CrossAttention>,
    parameters: Parameters,
}

impl UNet {
    /// Builds the network `config` describes, with every weight from `ckpt`.
    pub fn load(config: &UNetConfig, ckpt: &Checkpoint) -> Result<UNet> {
        config.validate()?;
        let w = ckpt.root();
        let levels = config.levels()?;
        let n = levels.len();
        let mut crosses = Vec::new();
        let down = DownPath::load(&w, config, &mut crosses)?;
        // diffusers registers up_blocks before mid_block, which fixes the processor order.
        let up_depths = config.up_depths()?;
        let mut up = Vec::new();
        let mut prev = levels[n - 1].channels;
        for i in 0..n {
            let level = &levels[n - 1 - i];
            let cross = config.up_block_types[i] == "CrossAttnUpBlock2D";
            let shape = BlockShape {
                inputs: levels[(n - 1 - i).saturating_sub(1)].channels,
                outputs: level.channels,
                layers: config.layers_per_block + 1,
                attention: cross.then_some((up_depths[i], level.heads)),
                resample: i + 1 < n,
            };
            up.push(UpBlock::load(&w.sub(&format!("up_blocks.{i}")), &shape, prev, &down.spec, &mut crosses)?);
            prev = level.channels;
        }
        let mid = down.load_mid(&w, config, &mut crosses)?;
        let c0 = config.block_out_channels[0];
        Ok(UNet {
            config: config.clone(),
            dtype: ckpt.dtype(),
            down,
            mid,
            up,
            norm_out: GroupNorm::load(&w, "conv_norm_out", c0, config.norm_num_groups, config.norm_eps)?,
            conv_out: Conv2d::load(&w, "conv_out", c0, config.out_channels, 3, 1, 1)?,
            crosses,
            parameters: ckpt.parameters(),
        })
    }

    pub fn config(&self) -> &UNetConfig {
        &self.config
    }

    /// The weights on the device by diffusers name.
    pub fn parameters(&self) -> &Parameters {
        &self.parameters
    }

    /// Channels of every cross-attention in diffusers' `attn_processors` order. Cross-attention k
    /// is processor 2k + 1 (each transformer block registers attn1, then attn2), the number
    /// IP-Adapter files key their `ip_adapter.N.to_k_ip` weights by.
    pub fn cross_attention_channels(&self) -> Vec<usize> {
        self.crosses.iter().map(|c| c.channels).collect()
    }

    /// Every cross-attention, in the order of [`UNet::cross_attention_channels`].
    pub fn cross_attentions(&self) -> &[CrossAttention] {
        &self.crosses
    }

    /// Shapes [B, h, w, C] of the skip tensors (ControlNet down residuals) and of the mid block's
    /// output for a latent of h × w.
    pub fn residual_shapes(&self, batch: usize, h: usize, w: usize) -> (Vec<[usize; 4]>, [usize; 4]) {
        let c = &self.config.block_out_channels;
        let (mut h, mut w) = (h, w);
        let mut down = vec![[batch, h, w, c[0]]];
        for (i, &ch) in c.iter().enumerate() {
            down.extend(std::iter::repeat_n([batch, h, w, ch], self.config.layers_per_block));
            if i + 1 < c.len() {
                (h, w) = (h.div_ceil(2), w.div_ceil(2));
                down.push([batch, h, w, ch]);
            }
        }
        (down, [batch, h, w, c[c.len() - 1]])
    }

    /// Records one evaluation on `inputs`' shapes.
    pub fn record(&self, inputs: &UNetInputs) -> Result<UNetPass> {
        self.check(inputs)?;
        let ctx = inputs.sample.context();
        let mut g = Graph::new(&ctx, self.dtype)?;
        let down_cond =
            DownConditioning { context: inputs.encoder_hidden_states, ip: inputs.ip, hint: None, emb_add: None };
        let DownOutput { h, mut skips, emb_silu } =
            self.down.forward(&mut g, inputs.sample, inputs.timesteps, inputs.added, &down_cond)?;
        let cond = Conditioning { emb_silu: &emb_silu, context: inputs.encoder_hidden_states, ip: inputs.ip };
        let mut h = self.mid.forward(&mut g, &h, &cond)?;
        if let Some(control) = inputs.control {
            // After the mid block has read the down path's output, which is also the last skip.
            ops::add(&mut g.rec, &h, &control.mid, &h)?;
            for (skip, residual) in skips.iter().zip(&control.down) {
                ops::add(&mut g.rec, skip, residual, skip)?;
            }
        }
        for block in &self.up {
            h = block.forward(&mut g, h, &cond, &mut skips)?;
        }
        let h = self.norm_out.forward(&mut g, &h, true)?;
        let s = inputs.sample.shape();
        let output = ctx.zeros(&[s[0], s[1], s[2], self.config.out_channels], self.dtype)?;
        self.conv_out.forward_into(&mut g, &h, &output, false)?;
        Ok(UNetPass { recorded: g.finish()?, output })
    }

    /// Shapes and dtypes of the inputs, each mismatch named.
    fn check(&self, i: &UNetInputs) -> Result<()> {
        let bad = |what: String| Err(Error::Config(what));
        let s = i.sample.shape();
        let c = &self.config;
        if s.len() != 4 || s[3] != c.in_channels {
            return bad(format!("UNet sample must be [B, H, W, {}] (channels last), got {s:?}", c.in_channels));
        }
        let multiple = 1 << (c.block_out_channels.len() - 1);
        if !s[1].is_multiple_of(multiple) || !s[2].is_multiple_of(multiple) {
            return bad(format!(
                "latent size {}×{} must be a multiple of {multiple} ({} pixels) for this UNet",
                s[1],
                s[2],
                8 * multiple
            ));
        }
        let b = s[0];
        for t in [i.sample, i.encoder_hidden_states] {
            if t.dtype() != self.dtype {
                return bad(format!("UNet inputs must be {:?} like its weights", self.dtype));
            }
        }
        if i.timesteps.dtype() != Dtype::F32 || i.timesteps.numel() != b {
            return bad(format!("timesteps must be {b} f32 values, one per batch item"));
        }
        let e = i.encoder_hidden_states.shape();
        if e.len() != 3 || e[0] != b || e[2] != c.cross_attention_dim {
            return bad(format!("encoder_hidden_states must be [{b}, tokens, {}], got {e:?}", c.cross_attention_dim));
        }
        if let (Some(dim), Some((text, ids))) = (self.down.text_embeds_dim(), i.added) {
            if text.shape() != [b, dim] || text.dtype() != self.dtype {
                return bad(format!(
                    "text_embeds must be [{b}, {dim}] {:?}, got {:?} {:?}",
                    self.dtype,
                    text.shape(),
                    text.dtype()
                ));
            }
            if ids.shape() != [b, 6] || ids.dtype() != Dtype::F32 {
                return bad(format!("time_ids must be [{b}, 6] f32, got {:?} {:?}", ids.shape(), ids.dtype()));
            }
        }
        if let Some(control) = i.control {
            let (down, mid) = self.residual_shapes(b, s[1], s[2]);
            let got: Vec<&[usize]> = control.down.iter().map(|t| t.shape()).collect();
            let want: Vec<&[usize]> = down.iter().map(|d| d.as_slice()).collect();
            if got != want || control.mid.shape() != mid {
                return bad(format!(
                    "ControlNet residuals {got:?} + mid {:?} do not match the UNet's skips {want:?} + mid {mid:?}",
                    control.mid.shape()
                ));
            }
        }
        for adapter in i.ip {
            let t = adapter.tokens.shape();
            if t.len() != 3 || t[0] != b || t[2] != c.cross_attention_dim || adapter.layers.len() != self.crosses.len()
            {
                return bad(format!(
                    "IP-Adapter tokens {t:?} with {} layers; the UNet wants [{b}, n, {}] and {} layers",
                    adapter.layers.len(),
                    c.cross_attention_dim,
                    self.crosses.len()
                ));
            }
        }
        Ok(())
    }
}
