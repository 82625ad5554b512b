//! IP-Adapter for SDXL (h94/IP-Adapter `.safetensors` files): the image projection that turns
//! image-encoder features into extra context tokens (`ImageProjModel`, or the Plus `Resampler`),
//! and the per-cross-attention `to_k_ip`/`to_v_ip` weights the UNet's decoupled attention uses.

use crate::clip::ImageFeature;
use crate::error::{Error, Result};
use crate::ip_adapter::resampler::{Resampler, ResamplerDims};
use crate::layers::attention::{IpAdapterInput, IpLayer};
use crate::layers::nn::{Graph, LayerNorm, Linear};
use crate::unet::unet_2d_condition::UNet;
use crate::weights::{Checkpoint, Weights};
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use vkdiff_formats::Error as FileError;
use vkdiff_formats::SafeTensors;
use vkdiff_runtime::{Context, Dtype, Tensor};

/// Which image projection an adapter has, and so which encoder output it reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IpAdapterKind {
    /// `ImageProjModel` (ip-adapter_sdxl, ip-adapter_sdxl_vit-h): reads `image_embeds`.
    Plain,
    /// `Resampler` (ip-adapter-plus_sdxl_vit-h): reads `hidden_states[-2]`.
    Plus,
}

impl IpAdapterKind {
    /// The image-encoder output this kind projects.
    pub fn feature(self) -> ImageFeature {
        match self {
            IpAdapterKind::Plain => ImageFeature::ImageEmbeds,
            IpAdapterKind::Plus => ImageFeature::Penultimate,
        }
    }
}

/// `ImageProjModel`: tokens = LayerNorm(reshape(proj(image_embeds), [B, T, D])).
struct ImageProjModel {
    proj: Linear,
    norm: LayerNorm,
    embed_dim: usize,
    tokens: usize,
    dim: usize,
}

impl ImageProjModel {
    fn load(w: &Weights, embed_dim: usize, tokens: usize, dim: usize) -> Result<ImageProjModel> {
        let proj = Linear::load(w, "proj", embed_dim, tokens * dim, true)?;
        Ok(ImageProjModel { proj, norm: LayerNorm::load(w, "norm", dim, 1e-5)?, embed_dim, tokens, dim })
    }
}

/// (to_k_ip, to_v_ip) of processor N = 2k + 1 for each cross-attention k of `unet`, in host
/// memory: they project the image tokens once per conditioning, not once per step.
fn load_layers(ckpt: &Checkpoint, unet: &UNet) -> Result<Vec<(Tensor, Tensor)>> {
    let dim = unet.config().cross_attention_dim;
    let w = ckpt.root().in_host_memory().sub("ip_adapter");
    (unet.cross_attention_channels().iter().enumerate())
        .map(|(k, &c)| {
            let l = w.sub(&(2 * k + 1).to_string());
            Ok((l.tensor("to_k_ip.weight", &[c, dim])?, l.tensor("to_v_ip.weight", &[c, dim])?))
        })
        .collect()
}

enum Projection {
    Plain(ImageProjModel),
    Plus(Resampler),
}

/// One loaded adapter; [`IpAdapter::unet_input`] hands its layers to any number of UNet passes.
pub struct IpAdapter {
    ctx: Context,
    dtype: Dtype,
    projection: Projection,
    /// (to_k_ip, to_v_ip) per cross-attention, in the UNet's order.
    layers: Vec<(Tensor, Tensor)>,
}

impl IpAdapter {
    /// Reads an h94-style adapter (`image_proj.*`, `ip_adapter.{N}.to_{k,v}_ip.weight`) and checks
    /// every per-layer weight against `unet`'s cross-attentions.
    pub fn load(ctx: &Context, path: &Path, unet: &UNet, dtype: Dtype) -> Result<IpAdapter> {
        let pickle = || FileError::Format {
            path: path.to_path_buf(),
            why: "a PyTorch pickle (.bin); vkdiff reads IP-Adapters as .safetensors (h94/IP-Adapter ships both)".into(),
        };
        if pickle_extension(path) {
            return Err(pickle().into());
        }
        let file = SafeTensors::open(path).map_err(|e| if pickle_magic(path) { pickle() } else { e })?;
        let shapes: BTreeMap<String, Vec<usize>> =
            file.entries.iter().map(|(k, e)| (k.clone(), e.shape.clone())).collect();
        let at = path.display().to_string();
        let proj_shapes: BTreeMap<String, Vec<usize>> =
            shapes.iter().filter_map(|(k, s)| Some((k.strip_prefix("image_proj.")?.to_string(), s.clone()))).collect();
        let dim = unet.config().cross_attention_dim;
        if proj_shapes.is_empty() {
            return Err(Error::Checkpoint(format!("{at}: not an IP-Adapter (no `image_proj.*` tensors)")));
        }
        check_layers(&at, &shapes, unet)?;

        let ckpt = Checkpoint::single_file_part(ctx, file, "", None, dtype);
        let w = ckpt.root().sub("image_proj");
        let projection = if proj_shapes.contains_key("latents") {
            let dims = ResamplerDims::infer(&proj_shapes).map_err(|e| Error::Checkpoint(format!("{at}: {e}")))?;
            if dims.output_dims != dim {
                return Err(Error::Checkpoint(format!(
                    "{at}: the Resampler outputs {} channels; the UNet's cross_attention_dim is {dim}",
                    dims.output_dims
                )));
            }
            Projection::Plus(Resampler::load(&w, dims)?)
        } else if let Some(s) = proj_shapes.get("proj.weight").filter(|s| s.len() == 2) {
            if !s[0].is_multiple_of(dim) {
                return Err(Error::Checkpoint(format!(
                    "{at}: `image_proj.proj.weight` {s:?} is not whole tokens of the UNet's cross_attention_dim {dim}"
                )));
            }
            Projection::Plain(ImageProjModel::load(&w, s[1], s[0] / dim, dim)?)
        } else {
            return Err(Error::Checkpoint(format!(
                "{at}: no `image_proj.latents` (Plus) or `image_proj.proj.weight` (plain) tensor; other IP-Adapter \
                    variants (Full, FaceID) are not supported"
            )));
        };
        let layers = load_layers(&ckpt, unet)?;
        let unused = ckpt.unused();
        if !unused.is_empty() {
            return Err(Error::Checkpoint(format!(
                "{at}: tensors this IP-Adapter kind does not have: {}",
                unused.join(", ")
            )));
        }
        Ok(IpAdapter { ctx: ctx.clone(), dtype, projection, layers })
    }

    /// A plain adapter of `tokens` tokens over `embed_dim`-wide image embeds with random
    /// weights for `unet` (benchmarks of full-size models).
    pub fn random_plain(
        ctx: &Context,
        unet: &UNet,
        embed_dim: usize,
        tokens: usize,
        dtype: Dtype,
    ) -> Result<IpAdapter> {
        let ckpt = Checkpoint::random(ctx, dtype, 5);
        let dim = unet.config().cross_attention_dim;
        let projection =
            Projection::Plain(ImageProjModel::load(&ckpt.root().sub("image_proj"), embed_dim, tokens, dim)?);
        Ok(IpAdapter { ctx: ctx.clone(), dtype, projection, layers: load_layers(&ckpt, unet)? })
    }

    pub fn kind(&self) -> IpAdapterKind {
        match self.projection {
            Projection::Plain(_) => IpAdapterKind::Plain,
            Projection::Plus(_) => IpAdapterKind::Plus,
        }
    }

    /// Image tokens per image (4 for the plain SDXL adapters, 16 for Plus).
    pub fn num_tokens(&self) -> usize {
        match &self.projection {
            Projection::Plain(p) => p.tokens,
            Projection::Plus(r) => r.dims().queries,
        }
    }

    /// Projects encoder features of the kind's [`IpAdapterKind::feature`] — `image_embeds`
    /// [B, E] (plain) or `hidden_states[-2]` [B, N, E] (Plus) — into image tokens
    /// [B, num_tokens, cross_attention_dim], row-major f32.
    pub fn image_tokens(&self, features: &[f32], shape: &[usize]) -> Result<Vec<f32>> {
        let numel: usize = shape.iter().product();
        if numel != features.len() || numel == 0 {
            return Err(Error::Config(format!("IP-Adapter: {} feature values for shape {shape:?}", features.len())));
        }
        match (&self.projection, shape) {
            (Projection::Plain(p), &[b, e]) if e == p.embed_dim => {
                let mut g = Graph::new(&self.ctx, self.dtype)?;
                let x = self.ctx.upload(&[b, e], self.dtype, features)?;
                let y = p.proj.forward(&mut g, &x)?.reshape(&[b, p.tokens, p.dim])?;
                let out = p.norm.forward(&mut g, &y)?;
                g.rec.finish()?.run()?;
                Ok(out.download()?)
            }
            (Projection::Plus(r), &[b, n, e]) if e == r.dims().embed_dims => {
                r.forward(&self.ctx, self.dtype, features, b, n)
            }
            (Projection::Plain(p), _) => {
                Err(Error::Config(format!("IP-Adapter takes image_embeds [B, {}], got {shape:?}", p.embed_dim)))
            }
            (Projection::Plus(r), _) => Err(Error::Config(format!(
                "IP-Adapter Plus takes hidden_states[-2] [B, tokens, {}], got {shape:?}",
                r.dims().embed_dims
            ))),
        }
    }

    /// The UNet's input for one pass: `tokens` [batch, k·num_tokens, cross_attention_dim] from
    /// [`IpAdapter::image_tokens`] (k images per batch item, their tokens one after another as
    /// diffusers flattens them; e.g. negative and positive stacked for guidance), uploaded, with
    /// this adapter's layers (shared, not copied) and each layer's scale.
    pub fn unet_input(&self, tokens: &[f32], batch: usize, scales: Vec<f32>) -> Result<IpAdapterInput> {
        if scales.len() != self.layers.len() {
            return Err(Error::Config(format!("IP-Adapter: {} scales for {} layers", scales.len(), self.layers.len())));
        }
        let (t, d) = (self.num_tokens(), self.dim());
        let per_item = tokens.len() / (batch * d).max(1);
        if batch == 0 || per_item == 0 || tokens.len() != batch * per_item * d || !per_item.is_multiple_of(t) {
            return Err(Error::Config(format!(
                "IP-Adapter: {} token values are not [{batch}, k·{t}, {d}]",
                tokens.len()
            )));
        }
        let layers = self
            .layers
            .iter()
            .map(|(k, v)| IpLayer {
                to_k_ip: Linear { weight: k.clone(), bias: None },
                to_v_ip: Linear { weight: v.clone(), bias: None },
            })
            .collect();
        Ok(IpAdapterInput { tokens: self.ctx.upload(&[batch, per_item, d], self.dtype, tokens)?, scales, layers })
    }

    /// Width of the image tokens, the UNet's cross_attention_dim.
    fn dim(&self) -> usize {
        match &self.projection {
            Projection::Plain(p) => p.dim,
            Projection::Plus(r) => r.dims().output_dims,
        }
    }
}

fn pickle_extension(path: &Path) -> bool {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    matches!(ext.as_deref(), Some("bin" | "pt" | "pth" | "ckpt"))
}

/// A file that is not safetensors but starts as torch.save's zip or a bare pickle does.
fn pickle_magic(path: &Path) -> bool {
    let mut head = [0u8; 2];
    std::fs::File::open(path).and_then(|mut f| std::io::Read::read_exact(&mut f, &mut head)).is_ok()
        && (head == *b"PK" || head[0] == 0x80)
}

/// The adapter's per-layer ids must be exactly 1, 3, …, 2n − 1 for the UNet's n cross-attentions,
/// each pair [channels, cross_attention_dim].
fn check_layers(at: &str, shapes: &BTreeMap<String, Vec<usize>>, unet: &UNet) -> Result<()> {
    let crosses = unet.cross_attention_channels();
    let dim = unet.config().cross_attention_dim;
    let mut ids = BTreeSet::new();
    for name in shapes.keys().filter(|k| k.starts_with("ip_adapter.")) {
        let id = name.split('.').nth(1).and_then(|s| s.parse::<usize>().ok());
        ids.insert(id.ok_or_else(|| Error::Checkpoint(format!("{at}: unexpected tensor `{name}`")))?);
    }
    let want: BTreeSet<usize> = (0..crosses.len()).map(|k| 2 * k + 1).collect();
    if ids != want {
        let list = |s: &BTreeSet<usize>| match (s.first(), s.last()) {
            (Some(a), Some(b)) => format!("{} ids {a}..={b}", s.len()),
            _ => "none".to_string(),
        };
        return Err(Error::Checkpoint(format!(
            "{at}: the adapter has per-layer weights for {} (`ip_adapter.N.*`) but this UNet has {} cross-attentions \
                (odd N 1..={}); an adapter for another UNet?",
            list(&ids),
            crosses.len(),
            (2 * crosses.len()).saturating_sub(1)
        )));
    }
    for (k, &c) in crosses.iter().enumerate() {
        for which in ["to_k_ip", "to_v_ip"] {
            let name = format!("ip_adapter.{}.{which}.weight", 2 * k + 1);
            match shapes.get(&name) {
                Some(s) if *s == [c, dim] => {}
                Some(s) => {
                    return Err(Error::Checkpoint(format!(
                        "{at}: `{name}` is {s:?}; this UNet's cross-attention {k} wants [{c}, {dim}] (channels, \
                        cross_attention_dim): an adapter for another UNet?"
                    )))
                }
                None => return Err(Error::Checkpoint(format!("{at}: tensor `{name}` is missing"))),
            }
        }
    }
    Ok(())
}
