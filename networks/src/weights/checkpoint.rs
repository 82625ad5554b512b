//! Checkpoints: safetensors files (or random weights, for benchmarks) seen through the names of
//! the diffusers module tree. Each module asks a [`Weights`] view scoped to its own prefix for its
//! tensors; the single-file layout is a renaming at this level, not a second path through the
//! networks.

use crate::error::{Error, Result};
use crate::weights::diffusers_files::diffusers_weight_files;
use crate::weights::original_names::{OriginalNames, StoredAs};
use crate::weights::parameters::{ParamLayout, Parameter, Parameters};
use std::collections::{BTreeSet, HashMap};
use std::path::Path;
use std::sync::Mutex;
use vkdiff_formats::{decode, SafeTensors, SourceDtype};
use vkdiff_runtime::ops::oihw_to_ohwi;
use vkdiff_runtime::{Context, Dtype, Placement, Tensor};

// One per checkpoint, so the size of the file variant costs nothing worth a box.
#[allow(clippy::large_enum_variant)]
enum Source {
    Files {
        files: Vec<SafeTensors>,
        /// Stored name → index into `files`.
        index: HashMap<String, usize>,
        /// Prefix stored names carry below the requested ones.
        prefix: String,
        /// Renaming from diffusers names to the original layout's, for single files.
        original: Option<OriginalNames>,
        /// A leading module level of the requested names that the files leave out.
        omitted: Option<String>,
        describe: String,
    },
    /// Every tensor drawn on request with a fan-in scale: full-size networks for benchmarks.
    Random { seed: u64 },
}

/// Weights for one network, converted to the run precision as they are uploaded.
pub struct Checkpoint {
    ctx: Context,
    dtype: Dtype,
    source: Source,
    used: Mutex<BTreeSet<String>>,
    placed: Mutex<Parameters>,
    /// Every (diffusers name, PyTorch shape) asked for, in order (see [`Checkpoint::requests`]).
    requested: Mutex<Vec<(String, Vec<usize>)>>,
}

impl Checkpoint {
    /// The weights `stem[.fp16].safetensors` (sharded or not) of a diffusers component folder.
    pub(crate) fn diffusers(ctx: &Context, folder: &Path, stem: &str, dtype: Dtype) -> Result<Checkpoint> {
        let files = diffusers_weight_files(folder, stem, dtype)?;
        Ok(Checkpoint::from_files(ctx, dtype, files, "", None, format!("{} (diffusers layout)", folder.display())))
    }

    /// One file of a component's weights stored under diffusers' names (SDXL-Lightning's UNet).
    pub(crate) fn diffusers_file(ctx: &Context, file: SafeTensors, dtype: Dtype) -> Checkpoint {
        let describe = format!("{} (diffusers layout)", file.path.display());
        Checkpoint::from_files(ctx, dtype, vec![file], "", None, describe)
    }

    /// The tensors under `prefix` of an original single-file checkpoint, renamed by `names`.
    pub(crate) fn single_file_part(
        ctx: &Context,
        file: SafeTensors,
        prefix: &str,
        names: Option<OriginalNames>,
        dtype: Dtype,
    ) -> Checkpoint {
        let describe = format!("{} (single-file layout)", file.path.display());
        Checkpoint::from_files(ctx, dtype, vec![file], prefix, names, describe)
    }

    /// Random weights of whatever shapes the network asks for (benchmarks of full-size models).
    pub fn random(ctx: &Context, dtype: Dtype, seed: u64) -> Checkpoint {
        Checkpoint {
            ctx: ctx.clone(),
            dtype,
            source: Source::Random { seed },
            used: Mutex::default(),
            placed: Mutex::default(),
            requested: Mutex::default(),
        }
    }

    fn from_files(
        ctx: &Context,
        dtype: Dtype,
        files: Vec<SafeTensors>,
        prefix: &str,
        original: Option<OriginalNames>,
        describe: String,
    ) -> Checkpoint {
        let mut index = HashMap::new();
        for (i, f) in files.iter().enumerate() {
            for name in f.entries.keys() {
                index.insert(name.clone(), i);
            }
        }
        let source = Source::Files { files, index, prefix: prefix.into(), original, omitted: None, describe };
        Checkpoint {
            ctx: ctx.clone(),
            dtype,
            source,
            used: Mutex::default(),
            placed: Mutex::default(),
            requested: Mutex::default(),
        }
    }

    /// The whole checkpoint as a view.
    pub fn root(&self) -> Weights<'_> {
        Weights { ckpt: self, prefix: String::new(), placement: Placement::Device }
    }

    /// The run precision weights are converted to.
    pub fn dtype(&self) -> Dtype {
        self.dtype
    }

    /// Every weight uploaded so far, by diffusers name: after a network is built from this
    /// checkpoint, its parameters on the device.
    pub fn parameters(&self) -> Parameters {
        self.placed.lock().unwrap().clone()
    }

    fn place(&self, name: String, tensor: Tensor, torch_shape: &[usize], layout: ParamLayout) {
        self.placed.lock().unwrap().insert(name, Parameter { tensor, torch_shape: torch_shape.to_vec(), layout });
    }

    /// Every tensor the network built from this random checkpoint asked for, by diffusers name
    /// with its PyTorch shape, each once, in the order first asked (empty for files).
    pub fn requests(&self) -> Vec<(String, Vec<usize>)> {
        self.requested.lock().unwrap().clone()
    }

    fn note_request(&self, name: &str, shape: &[usize]) {
        // Only random checkpoints are asked (write_random_single_file): a file's loads skip it.
        if !matches!(self.source, Source::Random { .. }) {
            return;
        }
        let mut requested = self.requested.lock().unwrap();
        if !requested.iter().any(|(n, _)| n == name) {
            requested.push((name.to_string(), shape.to_vec()));
        }
    }

    /// The values a random checkpoint of `seed` gives `name` of `shape` (PyTorch layout).
    pub fn random_values(seed: u64, name: &str, shape: &[usize]) -> Vec<f32> {
        random_values(seed, name, shape)
    }

    /// Stored tensors under the network's prefix that no module asked for.
    pub fn unused(&self) -> Vec<String> {
        let Source::Files { index, prefix, .. } = &self.source else { return Vec::new() };
        let used = self.used.lock().unwrap();
        let mut out: Vec<String> =
            index.keys().filter(|k| k.starts_with(prefix.as_str()) && !used.contains(*k)).cloned().collect();
        out.sort();
        out
    }

    /// This checkpoint with `level` (such as `text_model.`) left out of the stored names unless
    /// some stored name has it: transformers 5 saves `CLIPTextModel` without its `text_model`
    /// level, and loads either form.
    pub(crate) fn level_optional(mut self, level: &str) -> Checkpoint {
        if let Source::Files { index, prefix, omitted, .. } = &mut self.source {
            let with_level = format!("{prefix}{level}");
            if !index.keys().any(|k| k.starts_with(&with_level)) {
                *omitted = Some(level.to_string());
            }
        }
        self
    }

    /// Where a diffusers-named tensor is stored.
    fn stored_as(&self, name: &str) -> Option<StoredAs> {
        match &self.source {
            Source::Files { prefix, original, omitted, .. } => {
                let name = omitted.as_deref().and_then(|o| name.strip_prefix(o)).unwrap_or(name);
                let mut s = match original {
                    Some(o) => o.rename(name)?,
                    None => StoredAs::plain(name.to_string()),
                };
                s.name = format!("{prefix}{}", s.name);
                Some(s)
            }
            Source::Random { .. } => Some(StoredAs::plain(name.to_string())),
        }
    }

    fn describe_missing(&self, name: &str) -> String {
        match (&self.source, self.stored_as(name)) {
            (Source::Files { describe, .. }, Some(s)) if s.name != name => {
                format!("tensor `{}` (diffusers `{name}`) is missing from {describe}", s.name)
            }
            (Source::Files { describe, .. }, _) => format!("tensor `{name}` is missing from {describe}"),
            (Source::Random { .. }, _) => format!("tensor `{name}` is missing"),
        }
    }

    /// The stored shape of a diffusers-named tensor, if the checkpoint has it.
    pub(crate) fn stored_shape(&self, name: &str) -> Option<Vec<usize>> {
        match &self.source {
            Source::Files { files, index, .. } => {
                let at = self.stored_as(name)?;
                Some(files[*index.get(&at.name)?].entries[&at.name].shape.clone())
            }
            Source::Random { .. } => None,
        }
    }

    fn has(&self, name: &str) -> bool {
        match &self.source {
            Source::Files { index, .. } => self.stored_as(name).is_some_and(|s| index.contains_key(&s.name)),
            Source::Random { .. } => true,
        }
    }

    /// The stored bytes of `name` (its rows, for a part of a fused tensor), checked against the
    /// expected shape (trailing 1-sized dimensions are ignored, so a 1×1 conv and a linear weight
    /// read the same), and whether they hold the transpose.
    fn stored(&self, name: &str, shape: &[usize]) -> Result<Option<(SourceDtype, &[u8], bool)>> {
        let Source::Files { files, index, .. } = &self.source else { return Ok(None) };
        let at = self
            .stored_as(name)
            .filter(|s| index.contains_key(&s.name))
            .ok_or_else(|| Error::Checkpoint(self.describe_missing(name)))?;
        let file = &files[index[&at.name]];
        let entry = &file.entries[&at.name];
        let trim = |s: &[usize]| s[..s.iter().rposition(|&d| d != 1).map_or(0, |i| i + 1)].to_vec();
        let mut want = trim(shape);
        if at.transposed {
            want.reverse();
        }
        if let (Some((_, parts)), Some(first)) = (at.rows, want.first_mut()) {
            *first *= parts;
        }
        if trim(&entry.shape) != want {
            return Err(Error::Checkpoint(format!(
                "tensor `{}` in {} has shape {:?}; the config expects {want:?}",
                at.name,
                file.path.display(),
                entry.shape
            )));
        }
        if let SourceDtype::Other(what) = entry.dtype {
            return Err(Error::Checkpoint(format!(
                "tensor `{}` in {} is {what}; vkdiff reads F32, F16, BF16 and F8 (E4M3, E5M2)",
                at.name,
                file.path.display()
            )));
        }
        if let Some(scale) = fp8_scale(index, &at.name, entry.dtype) {
            return Err(Error::Checkpoint(format!(
                "tensor `{}` in {} is fp8 scaled by `{scale}` (ComfyUI's scaled fp8); vkdiff reads fp8 weights stored \
                 unscaled only: use the checkpoint's fp16 or bf16 release",
                at.name,
                file.path.display()
            )));
        }
        let mut bytes = file.bytes(entry);
        if let Some((part, parts)) = at.rows {
            let len = bytes.len() / parts;
            bytes = &bytes[part * len..(part + 1) * len];
        }
        self.used.lock().unwrap().insert(at.name);
        Ok(Some((entry.dtype, bytes, at.transposed)))
    }

    /// Values of `name` as f32 on the host.
    fn host(&self, name: &str, shape: &[usize]) -> Result<Vec<f32>> {
        self.note_request(name, shape);
        Ok(match self.stored(name, shape)? {
            Some((dtype, bytes, transposed)) => {
                let values = decode(dtype, bytes).expect("dtype checked by Checkpoint::stored");
                if transposed {
                    transpose(&values, shape[1], shape[0])
                } else {
                    values
                }
            }
            None => {
                let Source::Random { seed } = self.source else { unreachable!() };
                random_values(seed, name, shape)
            }
        })
    }

    /// `name` in the run precision, placed as `at` says; bytes already in it are streamed
    /// unconverted.
    fn tensor(&self, name: &str, shape: &[usize], at: Placement) -> Result<Tensor> {
        self.note_request(name, shape);
        if let Some((src, bytes, false)) = self.stored(name, shape)? {
            if matches!((src, self.dtype), (SourceDtype::F16, Dtype::F16) | (SourceDtype::F32, Dtype::F32)) {
                return Ok(self.ctx.upload_bytes_to(at, shape, self.dtype, bytes)?);
            }
        }
        self.upload(shape, &self.host(name, shape)?, at)
    }

    fn upload(&self, shape: &[usize], data: &[f32], at: Placement) -> Result<Tensor> {
        Ok(self.ctx.upload_to(at, shape, self.dtype, data)?)
    }
}

/// The scale an fp8 weight `name` is stored with, where the file has one beside it (ComfyUI's
/// scaled fp8 writes `….scale_weight`, its newer quantized format `….weight_scale`): read
/// unscaled, such weights would be silently wrong.
fn fp8_scale(index: &HashMap<String, usize>, name: &str, dtype: SourceDtype) -> Option<String> {
    if !matches!(dtype, SourceDtype::F8E4M3 | SourceDtype::F8E5M2) {
        return None;
    }
    let stem = name.strip_suffix("weight")?;
    [format!("{stem}scale_weight"), format!("{stem}weight_scale")].into_iter().find(|s| index.contains_key(s))
}

/// A checkpoint seen from one module: names are relative to its prefix.
#[derive(Clone)]
pub struct Weights<'a> {
    ckpt: &'a Checkpoint,
    prefix: String,
    /// Where this module's tensors go.
    placement: Placement,
}

impl<'a> Weights<'a> {
    /// The view of a child module (`w.sub("down_blocks.1").sub("resnets.0")`).
    pub fn sub(&self, name: &str) -> Weights<'a> {
        Weights { ckpt: self.ckpt, prefix: self.path(name), placement: self.placement }
    }

    /// This view with its tensors in host memory, which the device reads over the bus: for
    /// modules that run once per prompt or style image (encoders, the projections of the
    /// conditioning), so that the device's memory holds what every step reads.
    pub fn in_host_memory(&self) -> Weights<'a> {
        Weights { placement: Placement::Host, ..self.clone() }
    }

    /// The dotted module path this view is rooted at.
    pub fn prefix(&self) -> &str {
        &self.prefix
    }

    fn path(&self, name: &str) -> String {
        if self.prefix.is_empty() {
            name.to_string()
        } else {
            format!("{}.{name}", self.prefix)
        }
    }

    pub fn has(&self, name: &str) -> bool {
        self.ckpt.has(&self.path(name))
    }

    /// A tensor as stored, in the run precision.
    pub fn tensor(&self, name: &str, shape: &[usize]) -> Result<Tensor> {
        let t = self.ckpt.tensor(&self.path(name), shape, self.placement)?;
        self.ckpt.place(self.path(name), t.clone(), shape, ParamLayout::AsStored);
        Ok(t)
    }

    /// A tensor's values on the host, as f32.
    pub fn host(&self, name: &str, shape: &[usize]) -> Result<Vec<f32>> {
        self.ckpt.host(&self.path(name), shape)
    }

    /// A PyTorch conv weight [out, in, kh, kw] re-laid out as the kernels read it, [out, kh, kw, in].
    pub fn conv_weight(&self, name: &str, [o, i, kh, kw]: [usize; 4]) -> Result<Tensor> {
        let oihw = self.host(name, &[o, i, kh, kw])?;
        let t = self.ckpt.upload(&[o, kh, kw, i], &oihw_to_ohwi(&oihw, o, i, kh, kw), self.placement)?;
        self.ckpt.place(self.path(name), t.clone(), &[o, i, kh, kw], ParamLayout::ConvOhwi);
        Ok(t)
    }

    /// Several [rows_k, cols] weights stacked into one [Σ rows_k, cols] tensor (fused projections).
    /// Each part is placed as its row range where the device can bind it on its own.
    pub fn stacked(&self, names: &[&str], rows: usize, cols: usize) -> Result<Tensor> {
        // Grown as the parts are read: each part's shape is checked first, so a config asking
        // for absurd sizes fails on the stored shape instead of on the allocation.
        // Columns of 1 are biases, asked for in their PyTorch shape.
        let shape = if cols == 1 { vec![rows] } else { vec![rows, cols] };
        let mut data = Vec::new();
        for n in names {
            data.extend(self.host(n, &shape)?);
        }
        let t = self.ckpt.upload(&[names.len() * rows, cols], &data, self.placement)?;
        for (k, n) in names.iter().enumerate() {
            if let Ok(part) = t.narrow(k * rows, rows) {
                self.ckpt.place(self.path(n), part, &shape, ParamLayout::AsStored);
            }
        }
        Ok(t)
    }
}

/// The transpose of a row-major [rows, cols] matrix.
pub(crate) fn transpose(values: &[f32], rows: usize, cols: usize) -> Vec<f32> {
    (0..cols * rows).map(|i| values[(i % rows) * cols + i / rows]).collect()
}

/// Deterministic per-name values: U(−1, 1)/√fan_in for weights, 1 ± 0.1 for norm scales,
/// ±0.1 for biases, so a random full-size network stays in f16 range.
fn random_values(seed: u64, name: &str, shape: &[usize]) -> Vec<f32> {
    let mut state =
        name.bytes().fold(seed ^ 0xcbf2_9ce4_8422_2325, |h, b| (h ^ b as u64).wrapping_mul(0x100_0000_01b3)) | 1;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 23) as f32 - 1.0
    };
    let numel: usize = shape.iter().product();
    let (base, scale) = match shape.len() {
        1 if name.ends_with("weight") => (1.0, 0.1),
        1 => (0.0, 0.1),
        _ => (0.0, 1.0 / ((numel / shape[0]) as f32).sqrt()),
    };
    (0..numel).map(|_| base + scale * next()).collect()
}
