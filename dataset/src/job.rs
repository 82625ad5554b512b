//! `vkdiff dataset`'s one entry: the settings checked, the shard resolved, the style images read
//! and the folder opened before any model loads; then the run, and the merge by the process that
//! finds every image done (the whole run, or the last shard to finish: shards finishing together
//! write the same bytes, each file renamed into place whole).

use crate::disk::{check_margin, size, DiskGuard};
use crate::error::{Error, Result};
use crate::folder::{Dataset, Pending};
use crate::merge::{merge, Merged};
use crate::plan::Shard;
use crate::regenerate::{mark_flagged, Marked};
use crate::render_only::write_renders;
use crate::run::{generate, Progress, Report, RunOptions};
use crate::settings::DatasetSettings;
use std::path::Path;
use std::time::{Duration, Instant};
use vkdiff_pipeline::read_images;
use vkdiff_pipeline::RgbImage;
use vkdiff_pipeline::WorkflowModels;
use vkdiff_runtime::Context;
use vkdiff_setting::Message;

/// Which part of the set this process makes: `--shard I/N`, or `--shards N` with the index from
/// the environment (Slurm, Kubernetes), or the whole set.
pub struct ShardRequest {
    pub shard: Option<String>,
    pub shards: Option<u64>,
}

/// A checked dataset run of one process.
pub struct DatasetJob {
    settings: DatasetSettings,
    dataset: Dataset,
    styles: Vec<Vec<RgbImage>>,
    pending: Pending,
    shard: Shard,
    /// Where the shard came from, for the log.
    shard_source: String,
    options: RunOptions,
    disk: DiskGuard,
    /// The images `--regenerate-flagged` marked.
    marked: Option<Marked>,
}

/// What a run tells as it goes.
pub enum DatasetEvent<'a> {
    /// A line for the user: what is loading, what a LoRA touched, a prompt that is cut.
    Note(&'a str),
    /// Every model is loaded, in this time.
    Loaded(Duration),
    /// The loop's progress.
    Progress(Progress),
}

/// How the process ends once its images are made.
pub enum Finish {
    /// Every image of the set is made: `annotations.json` is written.
    Merged(Merged),
    /// Images of other shards are still to make.
    ShardDone { recorded: u64, total: u64 },
}

impl DatasetJob {
    /// Checks the run's options, resolves the shard (`env` reads the environment), reads the
    /// style images and opens (or resumes) the folder, before anything loads.
    pub fn new(
        settings: DatasetSettings,
        out: &Path,
        shard: ShardRequest,
        options: RunOptions,
        env: &dyn Fn(&str) -> Option<String>,
    ) -> Result<DatasetJob> {
        let (shard, shard_source) = Shard::resolve(shard.shard.as_deref(), shard.shards, env)?;
        if options.batch == 0 {
            return Err(Error::Setting(Message::setting("batch").then(" must be at least 1")));
        }
        let styles =
            settings.ip_sets.iter().map(|set| read_images(set)).collect::<vkdiff_pipeline::Result<Vec<_>>>()?;
        check_margin(out, options.min_free)?;
        let dataset = Dataset::open(out, &settings, options.versions)?;
        let marked = match &options.regenerate {
            Some(_) if settings.models.is_none() => return Err(Error::Config(
                "--regenerate-flagged: a --render-only set's images are its renders; there is nothing to sample again"
                    .into(),
            )),
            Some(kinds) => Some(mark_flagged(&dataset, kinds)?),
            None => None,
        };
        let pending = dataset.pending(shard)?;
        let disk = DiskGuard::new(&dataset, options.min_free, pending.done_bytes, pending.done);
        disk.check(pending.images())?;
        Ok(DatasetJob { settings, dataset, styles, pending, shard, shard_source, options, disk, marked })
    }

    pub fn settings(&self) -> &DatasetSettings {
        &self.settings
    }

    /// What `--regenerate-flagged` marked, in a line.
    pub fn regeneration_line(&self) -> Option<String> {
        self.marked.as_ref().map(|m| {
            let how = if m.resumed { "resuming the regeneration of" } else { "regenerating" };
            format!("{how} {} images the audit flagged, with new seeds (rounds in resamples.json)", m.images)
        })
    }

    /// Records found but not whole, each with why; their images are made again.
    pub fn redo(&self) -> &[String] {
        &self.pending.redo
    }

    /// One line: the set, this shard, what is left to make.
    pub fn plan_line(&self) -> String {
        let s = &self.settings;
        let estimate =
            self.estimated_size().map_or(String::new(), |b| format!("; about {} for the whole set", size(b)));
        format!(
            "{}: {} images of {}×{} from {} scenes; shard {}/{} ({}): {} to make, {} already done{estimate}",
            self.dataset.dir.display(),
            s.images(),
            s.sampling.width,
            s.sampling.height,
            s.count,
            self.shard.index,
            self.shard.count,
            self.shard_source,
            self.pending.images(),
            self.pending.done
        )
    }

    /// What this run writes, as it goes: the set's estimated size from it.
    pub fn disk(&self) -> DiskGuard {
        self.disk.clone()
    }

    /// The estimated size of the whole set on disk: images written (this run's, else earlier
    /// runs') times the set's images.
    pub fn estimated_size(&self) -> Option<u64> {
        self.disk.per_image().map(|per| (per * self.settings.images() as f64) as u64)
    }

    /// This process's shard, `I/N`.
    pub fn shard_name(&self) -> String {
        format!("{}/{}", self.shard.index, self.shard.count)
    }

    /// Images this process still has to make.
    pub fn todo(&self) -> u64 {
        self.pending.images()
    }

    /// Images of this shard made by earlier runs.
    pub fn done(&self) -> u64 {
        self.pending.done
    }

    /// Whether the run needs a Vulkan device: every set but a render-only one.
    pub fn needs_device(&self) -> bool {
        !self.settings.render_only()
    }

    /// Makes this shard's pending images (after which none are pending): loads the models on
    /// `ctx` and denoises, or for a render-only set writes the shaded renders.
    pub fn run(&mut self, ctx: Option<&Context>, events: &mut dyn FnMut(DatasetEvent)) -> Result<Report> {
        let pending = std::mem::take(&mut self.pending);
        let s = &self.settings;
        let Some(model_settings) = &s.models else {
            let progress = &mut |p| events(DatasetEvent::Progress(p));
            return write_renders(&self.dataset, &self.disk, s, pending, &self.options, progress);
        };
        let ctx = ctx.ok_or_else(|| Error::Config("a diffusion dataset needs a Vulkan device".into()))?;
        let start = Instant::now();
        let mut models = WorkflowModels::load(ctx, model_settings, &mut |line| events(DatasetEvent::Note(line)))?;
        // Each image decodes alone.
        let (width, height) = (s.sampling.width, s.sampling.height);
        if let Some(note) = models.sdxl.plan_vae(model_settings.vae_tiling, 1, width, height)?.note(width, height) {
            events(DatasetEvent::Note(&note));
        }
        // A template's expansions are not known yet; its plain siblings and the negative are.
        let plain = s.prompts.iter().zip(&s.templates).filter(|(_, t)| !t.is_template()).map(|(p, _)| p);
        let prompts = plain.chain(&s.negative_prompt);
        for warning in models.sdxl.cut_prompt_warnings(s.sampling.prompt_syntax, prompts) {
            events(DatasetEvent::Note(&warning));
        }
        events(DatasetEvent::Loaded(start.elapsed()));
        generate(&self.dataset, &self.disk, s, &mut models, &self.styles, pending, &self.options, &mut |p| {
            events(DatasetEvent::Progress(p))
        })
    }

    /// Merges the set if every image of it is made, by this process or others.
    pub fn finish(&self) -> Result<Finish> {
        let dir = &self.dataset.dir;
        let (recorded, total) = (Dataset::read(dir)?.recorded(), self.settings.images());
        if recorded == total {
            Ok(Finish::Merged(merge(dir, self.options.versions)?))
        } else {
            Ok(Finish::ShardDone { recorded, total })
        }
    }
}
