//! Merging LoRAs into the device weights in place, W += strength · scale · up · down, as GEMMs
//! accumulating into each weight's own view; and restoring the exact original bytes, kept on the
//! host before the first merge touches a weight (as ComfyUI keeps its backups on the CPU).

use crate::component::Component;
use crate::error::{Error, Result};
use crate::format::{LoraFile, Module};
use crate::names::{dictionaries, Resolved, Targets};
use half::f16;
use std::collections::BTreeMap;
use std::fmt;
use std::path::PathBuf;
use std::time::Instant;
use vkdiff_networks::{ParamLayout, Parameter};
use vkdiff_runtime::ops::{matmul, oihw_to_ohwi, Matmul};
use vkdiff_runtime::{dtype_size, Context, Dtype, Recorder, Tensor};

/// Factors uploaded per recording: few submits, bounded device memory, within a binding.
const CHUNK_BYTES: u64 = 64 << 20;
/// Unmatched module names listed in an error.
const LISTED: usize = 5;

/// What one LoRA changed, for the command line to print.
#[derive(Clone, Debug, Default)]
pub struct LoraSummary {
    pub path: PathBuf,
    pub strength: f32,
    pub unet: usize,
    pub text_encoder_1: usize,
    pub text_encoder_2: usize,
    /// Modules aimed at layers the network never runs (CLIP-L's last layer in SDXL).
    pub not_run: usize,
}

/// What a merge did.
#[derive(Clone, Debug, Default)]
pub struct Summary {
    pub loras: Vec<LoraSummary>,
    /// Distinct weights edited (and backed up).
    pub weights: usize,
    /// Wall time of the merge (backups, uploads and GEMMs), in seconds.
    pub seconds: f64,
}

impl fmt::Display for Summary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for l in &self.loras {
            write!(
                f,
                "LoRA {} at {}: {} UNet, {} CLIP-L, {} bigG modules",
                l.path.display(),
                l.strength,
                l.unet,
                l.text_encoder_1,
                l.text_encoder_2
            )?;
            if l.not_run > 0 {
                write!(f, " ({} aimed at layers the model never runs, skipped)", l.not_run)?;
            }
            writeln!(f)?;
        }
        write!(f, "{} weights merged in {:.2} s", self.weights, self.seconds)
    }
}

/// A weight's original contents on the host, in its storage dtype so that restoring is exact.
enum Original {
    F32(Vec<f32>),
    F16(Vec<f16>),
}

struct Backup {
    tensor: Tensor,
    original: Original,
}

/// The LoRAs merged into one set of networks. Use one merger per set of networks.
#[derive(Default)]
pub struct LoraMerger {
    backups: BTreeMap<(Component, String), Backup>,
    merged: bool,
}

/// One GEMM: weight view += alpha · up · down.
struct Job<'a> {
    file: &'a LoraFile,
    module: &'a Module,
    name: String,
    param: Parameter,
    alpha: f32,
}

impl LoraMerger {
    pub fn new() -> LoraMerger {
        LoraMerger::default()
    }

    /// Whether the weights currently hold merged LoRAs.
    pub fn is_merged(&self) -> bool {
        self.merged
    }

    /// Restores any earlier merge, then merges `loras` (each with its strength; their deltas add).
    /// On an error nothing stays merged.
    pub fn apply(&mut self, targets: &Targets, loras: &[(&LoraFile, f32)]) -> Result<Summary> {
        self.restore()?;
        let start = Instant::now();
        let (jobs, summaries) = plan(targets, loras)?;
        // Back up what this merge touches; backups of weights it leaves alone are dropped.
        let mut keep = BTreeMap::new();
        for job in &jobs {
            let key = (job.module.component, job.name.clone());
            if keep.contains_key(&key) {
                continue;
            }
            let backup = match self.backups.remove(&key) {
                Some(b) => b,
                None => backup(&job.param.tensor)?,
            };
            keep.insert(key, backup);
        }
        self.backups = keep;
        self.merged = true;
        if let Err(e) = run_jobs(&jobs) {
            self.restore()?;
            return Err(e);
        }
        Ok(Summary { loras: summaries, weights: self.backups.len(), seconds: start.elapsed().as_secs_f64() })
    }

    /// Drops the backups of `component`'s weights, whose network is being freed: they could
    /// not be restored, and the backups would keep its device memory alive.
    pub fn forget(&mut self, component: Component) {
        self.backups.retain(|(c, _), _| *c != component);
    }

    /// Puts back the original weights, bit for bit.
    pub fn restore(&mut self) -> Result<()> {
        if !self.merged {
            return Ok(());
        }
        for b in self.backups.values() {
            match &b.original {
                Original::F32(v) => b.tensor.write(v)?,
                Original::F16(v) => b.tensor.write(&v.iter().map(|x| x.to_f32()).collect::<Vec<_>>())?,
            }
        }
        self.merged = false;
        Ok(())
    }
}

fn backup(t: &Tensor) -> Result<Backup> {
    let values = t.download()?;
    // f16 → f32 → f16 is exact, so the f16 copy holds the stored bits.
    let original = match t.dtype() {
        Dtype::F32 => Original::F32(values),
        Dtype::F16 => Original::F16(values.into_iter().map(f16::from_f32).collect()),
    };
    Ok(Backup { tensor: t.clone(), original })
}

/// Resolves every module of every LoRA to its weight, checking shapes; unmatched modules are one
/// error per file, listing a few.
fn plan<'a>(targets: &Targets<'a>, loras: &[(&'a LoraFile, f32)]) -> Result<(Vec<Job<'a>>, Vec<LoraSummary>)> {
    let dicts = dictionaries(targets)?;
    let mut jobs = Vec::new();
    let mut summaries = Vec::new();
    for &(file, strength) in loras {
        let mut s = LoraSummary { path: file.path.clone(), strength, ..Default::default() };
        let mut unmatched = Vec::new();
        for module in &file.modules {
            let resolved = dicts.get(&module.component).map_or(Resolved::Missing, |d| d.resolve(&module.address));
            let (name, param) = match resolved {
                Resolved::Weight(name, param) => (name, param),
                Resolved::NotRun => {
                    s.not_run += 1;
                    continue;
                }
                Resolved::Missing => {
                    unmatched.push(module.key.as_str());
                    continue;
                }
            };
            let trim = |s: &[usize]| s[..s.iter().rposition(|&d| d != 1).map_or(0, |i| i + 1)].to_vec();
            if trim(&module.delta_shape()) != trim(&param.torch_shape) {
                let (key, expected, found) = (module.key.clone(), param.torch_shape.clone(), module.delta_shape());
                return Err(Error::Shape { path: file.path.clone(), key, weight: name, expected, found });
            }
            *match module.component {
                Component::Unet => &mut s.unet,
                Component::TextEncoder1 => &mut s.text_encoder_1,
                Component::TextEncoder2 => &mut s.text_encoder_2,
            } += 1;
            jobs.push(Job { file, module, param: param.clone(), alpha: strength * module.scale, name });
        }
        if !unmatched.is_empty() {
            let mut listed = unmatched.iter().take(LISTED).map(|k| format!("`{k}`")).collect::<Vec<_>>().join(", ");
            if unmatched.len() > LISTED {
                listed.push_str(&format!(" and {} more", unmatched.len() - LISTED));
            }
            return Err(Error::Unmatched { path: file.path.clone(), count: unmatched.len(), listed });
        }
        summaries.push(s);
    }
    Ok((jobs, summaries))
}

/// Records the jobs, factors packed into a few uploads per storage dtype.
fn run_jobs(jobs: &[Job]) -> Result<()> {
    let mut packs: Vec<Pack> = Vec::new();
    for job in jobs.iter().filter(|j| j.alpha != 0.0) {
        let t = &job.param.tensor;
        let i = match packs.iter().position(|p| p.dtype == t.dtype()) {
            Some(i) => i,
            None => {
                packs.push(Pack::new(t.context(), t.dtype()));
                packs.len() - 1
            }
        };
        packs[i].add(job)?;
        if packs[i].bytes() >= CHUNK_BYTES {
            packs[i].flush()?;
        }
    }
    packs.iter_mut().try_for_each(Pack::flush)
}

/// Factors of several jobs in one host buffer, each at an offset the device can bind.
struct Pack {
    ctx: Context,
    dtype: Dtype,
    /// Offsets in elements are multiples of this.
    align: usize,
    data: Vec<f32>,
    /// (weight view, up offset, down offset, out, k (rank), n, alpha).
    gemms: Vec<(Tensor, usize, usize, usize, usize, usize, f32)>,
}

impl Pack {
    fn new(ctx: Context, dtype: Dtype) -> Pack {
        let align = (ctx.info().binding_alignment() as usize).div_ceil(dtype_size(dtype));
        Pack { ctx, dtype, align, data: Vec::new(), gemms: Vec::new() }
    }

    fn bytes(&self) -> u64 {
        (self.data.len() * dtype_size(self.dtype)) as u64
    }

    fn push(&mut self, values: &[f32]) -> usize {
        let at = self.data.len().next_multiple_of(self.align);
        self.data.resize(at, 0.0);
        self.data.extend_from_slice(values);
        at
    }

    fn add(&mut self, job: &Job) -> Result<()> {
        let (up, mut down) = job.file.factors(job.module)?;
        let d = &job.module.down_shape;
        let (out, r) = (job.module.up_shape[0], d[0]);
        if job.param.layout == ParamLayout::ConvOhwi && d.len() == 4 {
            // The down factor [r, in, kh, kw] re-laid out as the weights are, [r, kh, kw, in].
            down = oihw_to_ohwi(&down, d[0], d[1], d[2], d[3]);
        }
        let n = down.len() / r;
        let (a, b) = (self.push(&up), self.push(&down));
        self.gemms.push((job.param.tensor.clone(), a, b, out, r, n, job.alpha));
        Ok(())
    }

    fn flush(&mut self) -> Result<()> {
        if self.gemms.is_empty() {
            return Ok(());
        }
        let factors = self.ctx.upload(&[self.data.len()], self.dtype, &self.data)?;
        let mut rec = Recorder::new(&self.ctx, false)?;
        for (c, a, b, m, k, n, alpha) in self.gemms.drain(..) {
            let up = factors.narrow(a, m * k)?.reshape(&[m, k])?;
            let down = factors.narrow(b, k * n)?.reshape(&[k, n])?;
            let spec = Matmul { alpha, accumulate: true, ..Matmul::dense(m, n, k, false) };
            matmul(&mut rec, &up, &down, None, &c, &spec)?;
        }
        rec.finish()?.run()?;
        self.data.clear();
        Ok(())
    }
}
