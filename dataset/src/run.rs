//! The dataset loop: scenes from the renderer thread, batched through one recorded denoiser,
//! decoded, and handed to the writer thread (`finish.rs`), which encodes and writes each image's
//! files and then its record. Prompts and style-image sets are encoded once each and reused; a
//! template's expansions are encoded as images bring them, cached by their text.

use super::disk::DiskGuard;
use super::finish::{finish, start_writer, Finished, Item};
use super::folder::{Dataset, Pending, VersionChange};
use super::plan::{choose, image_seed, resampled_seed, Choice};
use super::regenerate::read_rounds;
use super::scenes::{render_scenes, SceneImage};
use super::settings::DatasetSettings;
use super::stop::{interrupted, stop_requested};
use crate::error::{Error, Result};
use std::collections::{HashMap, VecDeque};
use std::sync::mpsc::{Receiver, SyncSender, TryRecvError};
use std::time::{Duration, Instant};
use vkdiff_pipeline::Conditioning;
use vkdiff_pipeline::RgbImage;
use vkdiff_pipeline::WorkflowModels;
use vkdiff_pipeline::{Denoiser, ItemInputs, Regions};

pub struct RunOptions {
    /// Images per UNet pass.
    pub batch: usize,
    /// Scene-rendering threads (0: one per core).
    pub threads: usize,
    /// Free space to leave on the dataset's file system (`--min-free`).
    pub min_free: u64,
    /// Whether a build of another version may add to a set (`--allow-version-change`).
    pub versions: VersionChange,
    /// Keep the text encoders once the prompts are encoded (a benchmark makes several sets from
    /// one load); otherwise their memory goes before the denoiser's comes, unless a prompt is a
    /// template, whose expansions are encoded as the images come.
    pub keep_text_encoders: bool,
    /// Make the images the audit flagged (with these kinds; all where empty) again with new
    /// seeds (`--regenerate-flagged`).
    pub regenerate: Option<Vec<String>>,
}

/// What the loop tells its caller as it goes.
pub enum Progress {
    /// `done` of the shard's `total` images are made (`done` counts earlier runs' too).
    Images { done: u64, total: u64 },
    /// Step `step` of `steps` of the batch being denoised.
    Step { step: usize, steps: usize },
}

/// Seconds spent per stage. The scene and write stages run on their own threads, beside the
/// others; `waiting` is the time the denoiser waited for scenes.
#[derive(Clone, Debug, Default)]
pub struct StageTimes {
    pub scene: Duration,
    /// Once per prompt, style set and batch shape: encoding them, recording the passes.
    pub setup: Duration,
    /// Per batch: the ControlNet's images encoded, the inputs written.
    pub guides: Duration,
    /// Each denoising step, batch after batch.
    pub steps: Vec<Duration>,
    pub vae: Duration,
    pub write: Duration,
    pub waiting: Duration,
}

impl StageTimes {
    /// All the denoising steps.
    pub fn denoise(&self) -> Duration {
        self.steps.iter().sum()
    }
}

pub struct Report {
    pub made: u64,
    pub times: StageTimes,
    /// How many times the denoiser was recorded: once per batch shape, and again after each
    /// decode that needed its memory ([`Sdxl::decode_fits_now`]).
    pub recordings: usize,
}

/// How many batches' worth of rendered images a batch may be chosen from.
const LOOKAHEAD: usize = 4;

/// How many encoded expansions of templates are kept beyond those the queued images use.
const CACHED_EXPANSIONS: usize = 64;

/// Makes the `pending` images of `dataset` with `models` (whose text encoders it releases once
/// the prompts are encoded, unless a prompt is a template); `styles` are the loaded images of
/// each of `settings.ip_sets`; `disk` is checked before each image and told what each wrote.
#[allow(clippy::too_many_arguments)]
pub fn generate(
    dataset: &Dataset,
    disk: &DiskGuard,
    settings: &DatasetSettings,
    models: &mut WorkflowModels,
    styles: &[Vec<RgbImage>],
    pending: Pending,
    options: &RunOptions,
    on_progress: &mut dyn FnMut(Progress),
) -> Result<Report> {
    let total = pending.done + pending.images();
    let start = Instant::now();
    // Every plain prompt once, first: batches group images by their prompts' token counts.
    let plain = settings.prompts.iter().zip(&settings.templates).filter(|(_, t)| !t.is_template());
    let texts = plain
        .map(|(p, _)| Ok((p.clone(), encode(models, settings, p)?)))
        .collect::<Result<HashMap<String, Conditioning>>>()?;
    // Each category's prompt, seen without guidance: the rows its pixels take.
    let syntax = settings.sampling.prompt_syntax;
    let region_texts = (settings.regions.prompts.iter())
        .map(|(_, _, p)| Ok(models.sdxl.encode_prompt_as(syntax, p, None, false)?))
        .collect::<Result<Vec<Conditioning>>>()?;
    // Every prompt is encoded: the encoders' memory goes before the denoiser's comes. A
    // template's expansions are known only as the images come: the encoders stay for them.
    if !options.keep_text_encoders && !settings.uses_templates() {
        models.sdxl.release_text_encoders();
    }
    let models = &*models;
    let stream = render_scenes(settings, pending.scenes, options.threads, 2 * options.batch);
    let (to_writer, writer) = start_writer(dataset.clone(), disk.clone(), options.batch);
    let mut run = Loop {
        rounds: read_rounds(&dataset.dir)?,
        settings,
        models,
        styles,
        pinned: texts.len(),
        texts,
        region_texts,
        tokens: HashMap::new(),
        times: StageTimes { setup: start.elapsed(), ..StageTimes::default() },
        denoiser: None,
        recordings: 0,
    };
    let made = run.all(&stream.images, &to_writer, (pending.done, total), disk, options.batch, on_progress);
    drop(to_writer);
    drop(stream.images);
    let written = writer.join().map_err(|_| Error::Config("the writer thread panicked".into()))?;
    run.times.scene = stream.thread.join().map_err(|_| scene_thread_panicked())?;
    // A failed write is the first failure when the loop stopped because it could not hand over.
    let made = match (made, written) {
        (_, Err(e)) => return Err(e),
        (Err(e), _) => return Err(e),
        (Ok(made), Ok(write)) => {
            run.times.write = write;
            made
        }
    };
    Ok(Report { made, times: run.times, recordings: run.recordings })
}

/// The error when the scene thread stopped on a bug: its images never came.
pub(crate) fn scene_thread_panicked() -> Error {
    Error::Config("the scene thread panicked (a bug: please report it with the command)".into())
}

/// `prompt`'s conditioning, with the set's negative prompt.
fn encode(models: &WorkflowModels, settings: &DatasetSettings, prompt: &str) -> Result<Conditioning> {
    let s = &settings.sampling;
    let negative = settings.negative_prompt.as_deref();
    Ok(models.sdxl.encode_prompt_as(s.prompt_syntax, prompt, negative, s.guided())?)
}

/// A recorded denoiser with the batch size and [`Loop::shape`] it was recorded for.
type RecordedDenoiser<'a> = (Denoiser<'a>, (usize, (usize, usize)));

struct Loop<'a> {
    /// Each regenerated image's round, by index (`--regenerate-flagged`).
    rounds: std::collections::BTreeMap<u64, u64>,
    settings: &'a DatasetSettings,
    models: &'a WorkflowModels,
    styles: &'a [Vec<RgbImage>],
    /// Each prompt's conditioning, by its text: the plain prompts', then templates' expansions.
    texts: HashMap<String, Conditioning>,
    /// How many of `texts` are plain prompts, kept for the whole run.
    pinned: usize,
    /// Each prompted category's conditioning, in the settings' order.
    region_texts: Vec<Conditioning>,
    tokens: HashMap<usize, Vec<f32>>,
    times: StageTimes,
    recordings: usize,
    denoiser: Option<RecordedDenoiser<'a>>,
}

impl<'a> Loop<'a> {
    fn all(
        &mut self,
        images: &Receiver<Result<SceneImage>>,
        to_writer: &SyncSender<Finished>,
        (mut done, total): (u64, u64),
        disk: &DiskGuard,
        batch: usize,
        on_progress: &mut dyn FnMut(Progress),
    ) -> Result<u64> {
        let mut made = 0;
        let mut queue: VecDeque<Item> = VecDeque::new();
        let mut open = true;
        loop {
            // Wait for a batch's worth; look further ahead only at what is already rendered.
            while open && queue.len() < batch {
                let start = Instant::now();
                let received = images.recv();
                self.times.waiting += start.elapsed();
                match received {
                    Ok(scene) => queue.push_back(self.item(scene?)?),
                    Err(_) => open = false,
                }
            }
            while open && queue.len() < LOOKAHEAD * batch {
                match images.try_recv() {
                    Ok(scene) => queue.push_back(self.item(scene?)?),
                    Err(TryRecvError::Empty) => break,
                    Err(TryRecvError::Disconnected) => open = false,
                }
            }
            let Some(fallback) = queue.front().map(|first| self.shape(first)) else { return Ok(made) };
            if stop_requested() {
                return Err(interrupted(done, total));
            }
            let items = self.take_batch(&mut queue, fallback, batch);
            let finished = self.batch(items, on_progress)?;
            self.forget_expansions(&queue);
            for finished in finished {
                disk.check(total.saturating_sub(done - made + disk.images_written()))?;
                to_writer.send(finished).map_err(|_| Error::Config("the writer stopped".into()))?;
                made += 1;
                done += 1;
                on_progress(Progress::Images { done, total });
            }
        }
    }

    /// Up to `batch` images of the queue for one pass. A pass takes images of one shape: the
    /// shape the denoiser is recorded for while a whole batch of it is queued, else the most
    /// common one (else `fallback`, the first image's), so that style sets of other sizes and
    /// prompts of other lengths neither make the denoiser record again at every batch nor cut
    /// batches short.
    fn take_batch(&self, queue: &mut VecDeque<Item>, fallback: (usize, usize), batch: usize) -> Vec<Item> {
        let queued = |n: (usize, usize)| queue.iter().filter(|i| self.shape(i) == n).count();
        let recorded = self.denoiser.as_ref().map(|(_, (_, shape))| *shape).filter(|&n| queued(n) >= batch);
        let most = queue.iter().map(|i| self.shape(i)).max_by_key(|&n| (queued(n), n == fallback));
        let want = recorded.or(most).unwrap_or(fallback);
        let (mut items, mut rest) = (Vec::with_capacity(batch), VecDeque::with_capacity(queue.len()));
        for item in queue.drain(..) {
            if items.len() < batch && self.shape(&item) == want {
                items.push(item);
            } else {
                rest.push_back(item);
            }
        }
        *queue = rest;
        items
    }

    /// The image's seed, prompt (a template expanded from the seed and the crop's categories,
    /// encoded now where its text is new) and style set.
    fn item(&mut self, scene: SceneImage) -> Result<Item> {
        let seed = resampled_seed(image_seed(self.settings.seed, scene.index), self.round(scene.index));
        let categories = scene.annotations.iter().map(|a| a.category_id);
        let (template, prompt) = self.settings.image_prompt(scene.scene, seed, categories)?;
        if !self.texts.contains_key(&prompt.prompt) {
            let start = Instant::now();
            let text = encode(self.models, self.settings, &prompt.prompt)?;
            self.texts.insert(prompt.prompt.clone(), text);
            self.times.setup += start.elapsed();
        }
        let style =
            (!self.settings.ip_sets.is_empty()).then(|| choose(seed, Choice::StyleSet, self.settings.ip_sets.len()));
        Ok(Item { scene, seed, template, prompt, style })
    }

    /// How many times image `index` was regenerated.
    fn round(&self, index: u64) -> u64 {
        self.rounds.get(&index).copied().unwrap_or(0)
    }

    /// Past [`CACHED_EXPANSIONS`], drops the encoded expansions no queued image takes.
    fn forget_expansions(&mut self, queue: &VecDeque<Item>) {
        if self.texts.len() > self.pinned + CACHED_EXPANSIONS {
            let s = self.settings;
            let plain = |text: &String| s.prompts.iter().zip(&s.templates).any(|(p, t)| p == text && !t.is_template());
            self.texts.retain(|text, _| plain(text) || queue.iter().any(|i| i.prompt.prompt == *text));
        }
    }

    fn style_images(&self, item: &Item) -> usize {
        item.style.map_or(0, |s| self.settings.ip_sets[s].len())
    }

    /// What a recorded pass is specific to: (style images, prompt tokens).
    fn shape(&self, item: &Item) -> (usize, usize) {
        (self.style_images(item), self.texts[&item.prompt.prompt].tokens)
    }

    /// Denoises and decodes one batch.
    fn batch(&mut self, items: Vec<Item>, on_progress: &mut dyn FnMut(Progress)) -> Result<Vec<Finished>> {
        let start = Instant::now();
        let sampling = &self.settings.sampling;
        for item in &items {
            if let Some(style) = item.style.filter(|s| !self.tokens.contains_key(s)) {
                let guide = self
                    .models
                    .image_guide(&self.styles[style])
                    .ok_or_else(|| Error::Config("style images without an IP-Adapter".into()))?;
                self.tokens.insert(style, guide.tokens(sampling.guided())?);
            }
        }
        let key = (items.len(), self.shape(&items[0]));
        if self.denoiser.as_ref().is_none_or(|(_, k)| *k != key) {
            self.denoiser = None; // the old recording's memory goes before the new one's comes
            let (styles, tokens) = key.1;
            let ip = self.models.ip_use(styles).filter(|_| styles > 0);
            self.recordings += 1;
            self.denoiser = Some((
                Denoiser::record(
                    &self.models.sdxl,
                    sampling,
                    &self.models.control_uses(),
                    ip,
                    key.0,
                    tokens,
                    self.region_texts.len(),
                )?,
                key,
            ));
        }
        let (denoiser, _) = self.denoiser.as_ref().expect("recorded above");
        // img2img: each image's shaded render through the VAE encoder.
        let inits = items
            .iter()
            .map(|item| {
                item.scene
                    .init
                    .as_ref()
                    .map(|(image, _)| self.models.sdxl.encode_init(image, sampling.width, sampling.height))
                    .transpose()
            })
            .collect::<vkdiff_pipeline::Result<Vec<_>>>()?;
        let regions: Vec<Option<Regions>> = (items.iter())
            .map(|item| item.scene.regions.clone().map(|masks| Regions { texts: &self.region_texts, masks }))
            .collect();
        let inputs: Vec<ItemInputs> = items
            .iter()
            .zip(&inits)
            .zip(&regions)
            .map(|((item, init), regions)| ItemInputs {
                init: init.as_ref(),
                regions: regions.as_ref(),
                strength: item.scene.strength.as_deref(),
                seed: item.seed,
                text: &self.texts[&item.prompt.prompt],
                control_images: self.models.control_images(&|kind| item.scene.control_image(kind)),
                ip_tokens: item.style.map(|s| self.tokens[&s].as_slice()),
            })
            .collect();
        self.times.setup += start.elapsed();
        let out = denoiser.run(&inputs, &mut |step, steps| on_progress(Progress::Step { step, steps }))?;
        self.times.guides += out.prepare;
        self.times.steps.extend(&out.steps);
        let shape = denoiser.latent_shape();
        if !self.models.sdxl.decode_fits_now() {
            // The plan counted the weights alone: the recorded passes make room, and are
            // recorded again for the next batch.
            self.denoiser = None;
        }
        let mut finished = Vec::with_capacity(items.len());
        for (item, latents) in items.into_iter().zip(out.latents) {
            let start = Instant::now();
            let image = self.models.sdxl.decode(&latents, shape)?;
            self.times.vae += start.elapsed();
            finished.push(finish(self.settings, self.models, self.round(item.scene.index), item, image));
        }
        Ok(finished)
    }
}
