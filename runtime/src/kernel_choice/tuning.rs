//! `VKDIFF_TUNE=1`: kernels chosen by timing them, per shape, as PyTorch's
//! `torch.backends.cudnn.benchmark` chooses cuDNN's. The first time a context records a matrix
//! product, a convolution or an attention of a shape, each kernel the device runs for it (the
//! matrix units' four- and eight-subgroup tiles, `VK_NV_cooperative_matrix2`'s probes) is
//! recorded on scratch tensors of the op's shapes and timed by the device's timestamps; the
//! shape takes the fastest that agrees with the default from then on, in this context. Off by default: which family wins
//! where is what a lent GPU measures with it, and the winners become the defaults.

use crate::context::Context;
use crate::error::{Error, Result};
use crate::kernel_choice::matrix_tile::MatrixTile;
use crate::kernel_choice::probe::ProbeChoice;
use crate::kernel_choice::trial::{relative_difference, AGREEMENT};
use crate::kernel_choice::tuned::{KernelPick, TunedShape, NOT_TUNED};
use crate::recorder::Recorder;
use crate::tensor::{uniform_values, Dtype, Tensor};
use std::sync::atomic::Ordering;

/// Timed runs of each candidate, after one run that compiles and warms it; the fastest counts.
const REPEATS: usize = 3;
/// How much faster another kernel must run than the one the settings pick to displace it, so
/// that a near tie keeps one choice from run to run (and the images their bits).
const MARGIN: f64 = 1.05;
/// What an op offers the tuner: a key naming everything its kernel choice and speed depend on,
/// its readable name, and whether the matrix units' tile applies to it.
pub(crate) struct Tunable {
    pub key: String,
    pub op: String,
    pub tiles: bool,
}

/// The parts of a shape's readable name that are on: `(on, text)` pairs joined in order.
pub(crate) fn name_parts(parts: &[(bool, &str)]) -> String {
    parts.iter().filter(|(on, _)| *on).map(|(_, text)| *text).collect()
}

/// Records one op with a pick, its inputs (in the order the op listed them) and its output:
/// the op's own, or the tuner's scratch tensors of the same shapes.
pub(crate) type RecordWith<'a> = &'a dyn Fn(&mut Recorder, KernelPick, &[&Tensor], &Tensor) -> Result<()>;

/// The pick an op records with where its settings are `probe` (and the context's tile): those
/// settings, or, with tuning on, the fastest of the distinct kernels the settings left open that
/// agree with theirs, timed now where this context has not timed the shape before. `inputs` are
/// the tensors the op reads; the timing reads copies of their shapes, filled with values.
pub(crate) fn pick(
    rec: &Recorder,
    (inputs, out): (&[&Tensor], &Tensor),
    probe: ProbeChoice,
    describe: impl FnOnce() -> Tunable,
    record: RecordWith,
) -> KernelPick {
    let ctx = rec.context();
    let settings = KernelPick { tile: ctx.choices().matrix_tile, probe };
    // Every kernel a setting adds (the matrix units' tiles, the probes) is f16's.
    if !ctx.tuning() || out.dtype() != Dtype::F16 {
        return settings;
    }
    let op = describe();
    // Tests and benchmarks switch a context's family; a shape is timed again on each.
    let key = format!("{} on {:?}", op.key, ctx.choices().gemm_family);
    if let Some(found) = ctx.shared.tuned.lock().unwrap().get(&key) {
        return found.pick;
    }
    let started = std::time::Instant::now();
    let tuned = tune(ctx, &op, settings, (inputs, out), record);
    ctx.shared.tuning_nanos.fetch_add(started.elapsed().as_nanos() as u64, Ordering::SeqCst);
    let pick = tuned.pick;
    ctx.shared.tuned.lock().unwrap().insert(key, tuned);
    pick
}

/// The picks the settings leave open, theirs first: the four-subgroup tile and each
/// eight-subgroup one where the tile is `auto` and applies, the probe or not where its setting
/// is `auto`.
fn candidates(op: &Tunable, settings: KernelPick) -> Vec<KernelPick> {
    let tiles = match (op.tiles, settings.tile) {
        (true, MatrixTile::Auto) => [MatrixTile::Auto].into_iter().chain(MatrixTile::EIGHT_SUBGROUPS).collect(),
        (_, tile) => vec![tile],
    };
    let probes = match settings.probe {
        ProbeChoice::Auto => vec![ProbeChoice::Auto, ProbeChoice::Matrix2],
        probe => vec![probe],
    };
    probes.iter().flat_map(|&probe| tiles.iter().map(move |&tile| KernelPick { tile, probe })).collect()
}

/// One candidate's recording, its kernels and its output.
struct Candidate {
    pick: KernelPick,
    kernels: String,
    recording: crate::Recording,
    out: Tensor,
}

/// A candidate's kernels and fastest milliseconds (NaN where it was not timed, or, in a note,
/// what became of it).
type Timed = (String, f64);

/// Times the distinct candidates of `op` on scratch tensors shaped as its own (inputs filled
/// with values in [-1, 1), the same for every candidate). A candidate that fails to record, to
/// run or to agree with the settings' own is noted and never chosen; where the scratch tensors
/// cannot be had (memory) or the settings' own kernels fail, the shape keeps the settings (the
/// op itself then reports any error of theirs).
fn tune(
    ctx: &Context,
    op: &Tunable,
    settings: KernelPick,
    (inputs, out): (&[&Tensor], &Tensor),
    record: RecordWith,
) -> TunedShape {
    let mut notes = Vec::new();
    let scratch: Result<Vec<Tensor>> = inputs
        .iter()
        .enumerate()
        .map(|(i, t)| ctx.upload(t.shape(), t.dtype(), &uniform_values(t.numel(), 11 + i as u64)))
        .collect();
    let kept = scratch.and_then(|scratch| {
        let reads: Vec<&Tensor> = scratch.iter().collect();
        let mut found: Vec<Candidate> = Vec::new();
        for pick in candidates(op, settings) {
            match record_candidate(ctx, pick, (&reads, out), record) {
                Ok(c) if found.iter().all(|f| f.kernels != c.kernels) => found.push(c),
                Ok(_) => {}
                Err(e) if found.is_empty() => return Err(e),
                Err(e) => notes.push((format!("{pick:?}: {e}"), f64::NAN)),
            }
        }
        time_candidates(found, &mut notes)
    });
    match kept {
        Ok(kept) => {
            let (timed, picks): (Vec<Timed>, Vec<KernelPick>) = kept.into_iter().unzip();
            let chosen = choose(&timed.iter().map(|(_, ms)| *ms).collect::<Vec<_>>());
            TunedShape {
                op: op.op.clone(),
                timed: timed.into_iter().chain(notes).collect(),
                chosen,
                pick: picks[chosen],
            }
        }
        Err(e) => TunedShape {
            op: op.op.clone(),
            timed: vec![(format!("{NOT_TUNED}: {e}"), f64::NAN)],
            chosen: 0,
            pick: settings,
        },
    }
}

/// `pick`'s recording of [`REPEATS`] runs of the op on `reads` into a zeroed output shaped as `out`.
fn record_candidate(
    ctx: &Context,
    pick: KernelPick,
    (reads, out): (&[&Tensor], &Tensor),
    record: RecordWith,
) -> Result<Candidate> {
    let out = ctx.zeros(out.shape(), out.dtype())?;
    let mut rec = Recorder::new(ctx, true)?;
    for _ in 0..REPEATS {
        record(&mut rec, pick, reads, &out)?;
    }
    let recording = rec.finish()?;
    Ok(Candidate { pick, kernels: kernel_list(&recording), recording, out })
}

/// Each candidate's kernels and fastest time (NaN where there is one: nothing to choose) with
/// its pick; a candidate past the first that fails to run, or whose output differs from the
/// first's (the settings' own) by more than the matrix units' trial allows, goes to `notes`.
fn time_candidates(found: Vec<Candidate>, notes: &mut Vec<Timed>) -> Result<Vec<(Timed, KernelPick)>> {
    if let [only] = &found[..] {
        return Ok(vec![((only.kernels.clone(), f64::NAN), only.pick)]);
    }
    let mut kept = Vec::new();
    let mut first: Option<Vec<f32>> = None;
    for c in found {
        let run = fastest_ms(&c.recording).and_then(|ms| Ok((ms, c.out.download()?)));
        let (ms, values) = match run {
            Ok(done) => done,
            Err(e) if first.is_none() => return Err(e),
            Err(e) => {
                notes.push((format!("{}: {e}", c.kernels), f64::NAN));
                continue;
            }
        };
        let difference = first.as_ref().map_or(0.0, |f| relative_difference(&values, f));
        if difference <= AGREEMENT {
            kept.push(((c.kernels, ms), c.pick));
        } else {
            notes.push((
                format!("{}: differs from the default kernel's by {difference:.2e} of its size", c.kernels),
                f64::NAN,
            ));
        }
        first.get_or_insert(values);
    }
    Ok(kept)
}

/// The recording's kernels in order, each once, as `vkdiff devices --compile` labels them.
fn kernel_list(recording: &crate::Recording) -> String {
    let labels: Vec<String> = recording.variants().into_iter().map(crate::variant_label).collect();
    labels.join(" + ")
}

/// The fastest of the recording's [`REPEATS`] runs of the op, from the device's timestamps, after
/// a run that compiles and warms its kernels.
fn fastest_ms(recording: &crate::Recording) -> Result<f64> {
    recording.run_submissions()?;
    let timings = recording.run_profiled()?;
    let per_run = timings.len() / REPEATS;
    Ok(timings.chunks(per_run.max(1)).map(|run| run.iter().map(|t| t.nanos).sum::<f64>()).fold(f64::INFINITY, f64::min)
        / 1e6)
}

/// Which of `ms` (the settings' own first) to take: the fastest, unless it is within [`MARGIN`]
/// of the first; the first where there is nothing to compare.
fn choose(ms: &[f64]) -> usize {
    let best = (0..ms.len()).min_by(|&a, &b| ms[a].total_cmp(&ms[b])).unwrap_or(0);
    if ms[best] * MARGIN < ms[0] {
        best
    } else {
        0
    }
}

impl Context {
    /// Whether ops time their kernels per shape and take the fastest (`VKDIFF_TUNE`).
    pub fn tuning(&self) -> bool {
        self.shared.tuning.load(Ordering::SeqCst)
    }

    /// Turns tuning on or off for recordings made from now on (tests and benchmarks); an error
    /// where the device writes no timestamps to time kernels by.
    pub fn set_tuning(&self, on: bool) -> Result<()> {
        if on && !self.info().timestamps() {
            return Err(Error::BadSetting(format!(
                "VKDIFF_TUNE=1: device `{}` writes no timestamps to time kernels with",
                self.info().name
            )));
        }
        self.shared.tuning.store(on, Ordering::SeqCst);
        Ok(())
    }

    /// One line on what tuning did, where this context tuned: the shapes timed, how many took
    /// another kernel than the settings', and the seconds it cost.
    pub fn tuning_summary(&self) -> Option<String> {
        let shapes = self.tuned_shapes();
        let seconds = self.shared.tuning_nanos.load(Ordering::SeqCst) as f64 / 1e9;
        let moved = shapes.iter().filter(|s| s.chosen != 0).count();
        self.tuning().then(|| {
            format!(
                "VKDIFF_TUNE: {} shapes had kernels to choose between; {moved} took another than the default, \
                 timed in {seconds:.1} s",
                shapes.len()
            )
        })
    }

    /// Every shape this context has tuned that had kernels to choose between (or that tuning
    /// could not time), by op and shape.
    pub fn tuned_shapes(&self) -> Vec<TunedShape> {
        let tuned = self.shared.tuned.lock().unwrap();
        let mut shapes: Vec<TunedShape> = tuned.values().filter(|s| s.reported()).cloned().collect();
        shapes.sort_by(|a, b| a.op.cmp(&b.op));
        shapes
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_what_the_settings_leave_open_is_tried_theirs_first() {
        let op = |tiles| Tunable { key: String::new(), op: String::new(), tiles };
        let pick = |tile, probe| KernelPick { tile, probe };
        let auto = pick(MatrixTile::Auto, ProbeChoice::Auto);
        let tiles = [MatrixTile::Auto, MatrixTile::Eight, MatrixTile::EightTall, MatrixTile::EightWide];
        let both: Vec<KernelPick> = [ProbeChoice::Auto, ProbeChoice::Matrix2]
            .into_iter()
            .flat_map(|probe| tiles.map(|tile| pick(tile, probe)))
            .collect();
        assert_eq!(candidates(&op(true), auto), both);
        assert_eq!(candidates(&op(false), auto), [auto, pick(MatrixTile::Auto, ProbeChoice::Matrix2)], "attention");
        let fixed = pick(MatrixTile::Four, ProbeChoice::Matrix2);
        assert_eq!(candidates(&op(true), fixed), [fixed], "both set");
    }

    #[test]
    fn another_kernel_displaces_the_settings_own_only_by_the_margin() {
        assert_eq!(choose(&[1.0, 0.5, 0.7]), 1);
        assert_eq!(choose(&[1.0, 0.97]), 0, "within 5 %");
        assert_eq!(choose(&[1.0, 2.0]), 0);
        assert_eq!(choose(&[f64::NAN]), 0, "one candidate, not timed");
    }
}
