//! How long one submission may run: recordings are split into chunks of bounded arithmetic,
//! so no submission runs into a GPU watchdog (Windows' TDR stops a GPU job after 2 s; amdgpu's
//! lockup timeout, 10 s, resets the GPU), and each wait has a limit. A recording's first run
//! submits each chunk alone and times it; later runs submit consecutive chunks together up to
//! a measured [`SubmitBudget::merge`], as each submission costs the GPU time of its own (an
//! H100, SDXL's UNet at 1024²: 181 ms an evaluation in 103 submissions, 161 ms in 5).

use crate::device::{DeviceInfo, DeviceKind};
use crate::settings::Settings;
use std::time::Duration;

/// Dispatches per submission, whatever their arithmetic: element-wise work and norms count no
/// FLOPs, and an SDXL evaluation has about 4,500 dispatches.
pub const DISPATCHES_PER_SUBMIT: u32 = 256;

/// Where a recording ends one submission and starts the next, and how long a wait may last.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SubmitBudget {
    /// Matrix-product FLOPs per submission (one dispatch past it ends the chunk).
    pub flops: f64,
    pub dispatches: u32,
    /// The longest wait for one submission before the device is taken as hung.
    pub timeout: Duration,
    /// The longer wait a run may take for each kernel the driver compiles in it (lavapipe, at
    /// its first dispatch), unless `VKDIFF_SUBMIT_TIMEOUT` sets the limit: one 128-row variant
    /// took Mesa 25 past 10 minutes at 16 lanes, Mesa 26.1 about 2 (docs/benchmark-log.md).
    pub compile_allowance: Duration,
    /// The longest run time, as the chunks' first run measured it, of a submission of several
    /// chunks; zero submits every chunk alone.
    pub merge: Duration,
}

impl SubmitBudget {
    /// The budget for `info` under `settings` (`VKDIFF_SUBMIT_GFLOP`, `VKDIFF_SUBMIT_TIMEOUT`,
    /// `VKDIFF_SUBMIT_MERGE`). Unless set, a CPU device (lavapipe, about 10–70 GFLOP/s) waits 10
    /// minutes per submission, and lavapipe 20 more for each kernel a run compiles; a GPU one
    /// minute: all far past a healthy chunk, so only a hang ends a run.
    pub fn for_device(info: &DeviceInfo, settings: &Settings) -> SubmitBudget {
        let seconds = if info.kind == DeviceKind::Cpu { 600.0 } else { 60.0 };
        SubmitBudget {
            flops: settings.submit_gflop * 1e9,
            dispatches: DISPATCHES_PER_SUBMIT,
            timeout: Duration::from_secs_f64(settings.submit_timeout.unwrap_or(seconds)),
            compile_allowance: match (info.lavapipe_mesa, settings.submit_timeout) {
                (Some(_), None) => Duration::from_secs(1200),
                _ => Duration::ZERO,
            },
            merge: Duration::from_secs_f64(settings.submit_merge),
        }
    }

    /// How many consecutive chunks each submission holds, given each chunk's run time alone:
    /// chunks join the submission before them while its time stays below `merge`.
    pub(crate) fn merged(&self, times: &[Duration]) -> Vec<usize> {
        let mut sizes: Vec<usize> = Vec::new();
        let mut sum = Duration::MAX;
        for &t in times {
            match sizes.last_mut() {
                Some(size) if sum.saturating_add(t) < self.merge => {
                    *size += 1;
                    sum += t;
                }
                _ => {
                    sizes.push(1);
                    sum = t;
                }
            }
        }
        sizes
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::device::tests::device;

    #[test]
    fn defaults_and_overrides() {
        let gpu = device(0, DeviceKind::Discrete, true);
        let budget = SubmitBudget::for_device(&gpu, &Settings::default());
        assert_eq!((budget.flops, budget.dispatches, budget.timeout), (1e11, 256, Duration::from_secs(60)));
        assert_eq!(budget.merge, Duration::from_millis(100));
        let cpu = device(0, DeviceKind::Cpu, true);
        assert_eq!(SubmitBudget::for_device(&cpu, &Settings::default()).timeout, Duration::from_secs(600));
        let set = Settings { submit_gflop: 2.5, submit_timeout: Some(0.5), submit_merge: 0.0, ..Settings::default() };
        let budget = SubmitBudget::for_device(&gpu, &set);
        assert_eq!((budget.flops, budget.timeout, budget.merge), (2.5e9, Duration::from_millis(500), Duration::ZERO));
        // Only lavapipe compiles at dispatch, and a set timeout is the limit itself.
        let mut lavapipe = cpu.clone();
        lavapipe.lavapipe_mesa = Some((25, 0));
        let allowance = |d: &DeviceInfo, s: &Settings| SubmitBudget::for_device(d, s).compile_allowance;
        assert_eq!(allowance(&lavapipe, &Settings::default()), Duration::from_secs(1200));
        assert_eq!(allowance(&lavapipe, &set), Duration::ZERO);
        assert_eq!(
            (allowance(&cpu, &Settings::default()), allowance(&gpu, &Settings::default())),
            (Duration::ZERO, Duration::ZERO)
        );
    }

    #[test]
    fn chunks_merge_while_their_times_stay_below_the_limit() {
        let ms = |v: &[u64]| v.iter().map(|&x| Duration::from_millis(x)).collect::<Vec<_>>();
        let budget = |merge: u64| SubmitBudget {
            flops: 1e11,
            dispatches: 256,
            timeout: Duration::from_secs(60),
            compile_allowance: Duration::ZERO,
            merge: Duration::from_millis(merge),
        };
        assert_eq!(budget(100).merged(&ms(&[30, 30, 30, 30, 30])), [3, 2]);
        // A chunk longer than the limit goes alone, and ends the submission before it.
        assert_eq!(budget(100).merged(&ms(&[10, 150, 10, 10])), [1, 1, 2]);
        assert_eq!(budget(0).merged(&ms(&[0, 0, 1])), [1, 1, 1]);
        assert_eq!(budget(100).merged(&[]), Vec::<usize>::new());
    }
}
