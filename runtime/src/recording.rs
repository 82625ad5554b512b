//! A finished recording ([`crate::Recorder::finish`]): run as often as asked, its submissions
//! merged once timed, and its dispatches timed where it was recorded to be.

use crate::context::Context;
use crate::error::{Result, VkContext};
use crate::recorder::{Recorder, Resources, QUERIES_PER_POOL};
use crate::submit::submit_groups_and_wait;
use crate::timing::Timing;
use ash::vk;
use std::sync::atomic::Ordering;
use std::sync::Mutex;
use vkdiff_kernels::Variant;

/// A finished command buffer that can be run any number of times.
pub struct Recording {
    ctx: Context,
    res: Resources,
    flops: f64,
    /// Chunks per submission, from the run that timed each chunk alone; none until then.
    merged: Mutex<Option<Vec<usize>>>,
}

impl Recording {
    pub(crate) fn new(ctx: Context, res: Resources, flops: f64) -> Recording {
        Recording { ctx, res, flops, merged: Mutex::new(None) }
    }

    /// The kernel variants this recording dispatches, each once, in the order first dispatched:
    /// what tests assert the kernel choice by.
    pub fn variants(&self) -> Vec<&'static Variant> {
        self.res.kernels.iter().map(|k| k.variant).collect()
    }

    /// Runs the recording to completion: the first time one submission per chunk, then as
    /// many chunks a submission as [`SubmitBudget::merge`] allows.
    pub fn run(&self) -> Result<()> {
        self.run_submissions()?;
        // Inside Context::profiled, a timed recording hands its dispatch times over.
        let collecting = !self.res.labels.is_empty() && self.ctx.shared.collected.lock().unwrap().is_some();
        if collecting {
            let timings = self.timings()?;
            self.ctx.shared.collected.lock().unwrap().get_or_insert_with(Vec::new).extend(timings);
        }
        Ok(())
    }

    /// Runs the recording and returns about how long each submission ran: from the end of the
    /// one before (the first: from its submission) to its own end, as the host saw them.
    pub fn run_submissions(&self) -> Result<Vec<std::time::Duration>> {
        let compiles = self.tell_compiles();
        let budget = self.ctx.choices().submit_budget;
        let mut merged = self.merged.lock().unwrap();
        let sizes = merged.clone().unwrap_or_else(|| vec![1; self.res.chunks.len()]);
        let mut rest = &self.res.chunks[..];
        let groups: Vec<&[vk::CommandBuffer]> = sizes
            .iter()
            .map(|&n| {
                let (group, after) = rest.split_at(n);
                rest = after;
                group
            })
            .collect();
        let times = submit_groups_and_wait(&self.ctx, &groups, budget.compile_allowance * compiles)?;
        *merged = match merged.take() {
            None => Some(budget.merged(&times)),
            // A merged submission twice as slow as its chunks were timed (clocks, a GPU shared
            // with other work): time them alone again.
            Some(_) if times.iter().zip(&sizes).any(|(&t, &n)| n > 1 && t > 2 * budget.merge) => None,
            kept => kept,
        };
        Ok(times)
    }

    /// The chunks a recording is split into (see [`SubmitBudget`]), each its own submission the
    /// first time it runs.
    pub fn chunks(&self) -> usize {
        self.res.chunks.len()
    }

    /// Tells the context's compile notice how many of this recording's kernels lavapipe will
    /// compile in this submission (those no earlier submission in this process dispatched), and
    /// returns that number.
    fn tell_compiles(&self) -> u32 {
        if self.ctx.info().lavapipe_mesa.is_none() {
            return 0;
        }
        let fresh = self.res.kernels.iter().filter(|k| !k.dispatched.swap(true, Ordering::SeqCst)).count();
        let notice = self.ctx.shared.compile_notice.lock().unwrap().clone();
        if let (Some(notice), true) = (notice, fresh > 0) {
            notice(fresh);
        }
        fresh as u32
    }

    /// Runs the recording and returns each dispatch's device time (recorded with `profile`).
    pub fn run_profiled(&self) -> Result<Vec<Timing>> {
        self.run_submissions()?;
        self.timings()
    }

    /// Each dispatch's device time in the last run (recorded with `profile`).
    fn timings(&self) -> Result<Vec<Timing>> {
        let n = self.res.labels.len();
        let mut stamps = vec![0u64; 2 * n];
        for (i, chunk) in stamps.chunks_mut(QUERIES_PER_POOL as usize).enumerate() {
            // SAFETY: the run has finished, so every query in range is available.
            unsafe {
                self.ctx.shared.device.get_query_pool_results(
                    self.res.query_pools[i],
                    0,
                    chunk,
                    vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
                )
            }
            .vk("vkGetQueryPoolResults")?;
        }
        let period = self.ctx.info().timestamp_period_ns as f64;
        let bits = self.ctx.info().timestamp_bits;
        Ok(self
            .res
            .labels
            .iter()
            .zip(stamps.chunks_exact(2))
            .map(|(&kernel, t)| Timing { kernel, nanos: stamp_ticks(t[0], t[1], bits) as f64 * period })
            .collect())
    }

    /// Floating-point operations of the matrix products one run does (GEMMs, convolutions and
    /// both products of attention, 2 per multiply-add), to hold a run's time against a peak.
    pub fn flops(&self) -> f64 {
        self.flops
    }

    /// Number of timed dispatches.
    pub fn dispatches(&self) -> usize {
        self.res.labels.len()
    }
}

/// Ticks from `start` to `end` on a counter of `bits` valid bits (`timestampValidBits`): the
/// bits above are undefined, and the counter may wrap between the two.
fn stamp_ticks(start: u64, end: u64, bits: u32) -> u64 {
    let mask = if bits >= 64 { u64::MAX } else { (1u64 << bits) - 1 };
    end.wrapping_sub(start) & mask
}

impl Context {
    /// Records with `f`, then runs the recording once.
    pub fn run(&self, f: impl FnOnce(&mut Recorder) -> Result<()>) -> Result<()> {
        self.run_listing(f).map(drop)
    }

    /// [`Context::run`], returning the kernel variants the recording dispatched.
    pub fn run_listing(&self, f: impl FnOnce(&mut Recorder) -> Result<()>) -> Result<Vec<&'static Variant>> {
        let mut rec = Recorder::new(self, false)?;
        f(&mut rec)?;
        let recording = rec.finish()?;
        recording.run()?;
        Ok(recording.variants())
    }
}

#[cfg(test)]
mod tests {
    use super::stamp_ticks;

    #[test]
    fn timestamps_keep_their_valid_bits_and_wrap() {
        assert_eq!(stamp_ticks(100, 250, 64), 150);
        // 36 valid bits (some GPUs): garbage above them, and a wrap between the stamps.
        let garbage = 0xabc0_0000_0000_0000;
        assert_eq!(stamp_ticks(garbage | 100, 250, 36), 150);
        assert_eq!(stamp_ticks((1 << 36) - 10, 5, 36), 15);
    }
}
