//! How long one submission may run: recordings are split into chunks of bounded arithmetic,
//! so no submission runs into a GPU watchdog (Windows' TDR stops a GPU job after 2 s; amdgpu's
//! lockup timeout, 10 s, resets the GPU), and each wait has a limit. A recording's first run
//! submits each chunk alone and times it; later runs submit consecutive chunks together up to
//! a measured [`SubmitBudget::merge`], as each submission costs the GPU time of its own (an
//! H100, SDXL's UNet at 1024²: 181 ms an evaluation in 103 submissions, 161 ms in 5).

use crate::device::{DeviceInfo, DeviceKind};
use crate::error::{Error, Result};
use std::time::Duration;

/// GFLOP per submission: about 40 ms on a mid-range GPU (an RTX 3060 at the 2.5 TFLOP/s vkdiff's
/// tiled f32 kernels reach on a 13 TFLOP/s card, estimated from the H200's 20 % of fp32 peak),
/// 0.2 s on an entry card at 0.6 TFLOP/s; attention, at about 40 % of the GEMM rate, 2.5× that.
pub const DEFAULT_SUBMIT_GFLOP: f64 = 100.0;
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
    /// The longest run time, as the chunks' first run measured it, of a submission of several
    /// chunks; zero submits every chunk alone.
    pub merge: Duration,
}

/// The default [`SubmitBudget::merge`]: a twentieth of Windows' TDR, so a device twice as slow
/// as when it was timed stays far from it, yet few enough submissions that their cost vanishes.
pub const DEFAULT_MERGE_SECONDS: f64 = 0.1;

impl SubmitBudget {
    /// The defaults for `info`, overridden by `VKDIFF_SUBMIT_GFLOP`, `VKDIFF_SUBMIT_TIMEOUT`
    /// (seconds) and `VKDIFF_SUBMIT_MERGE` (seconds, 0 for none). A CPU device (lavapipe, about 10–70 GFLOP/s) waits 10 minutes per submission, a
    /// GPU one minute: both far past a healthy chunk, so only a hang ends a run.
    pub fn for_device(info: &DeviceInfo, env: &dyn Fn(&str) -> Option<String>) -> Result<SubmitBudget> {
        let seconds = if info.kind == DeviceKind::Cpu { 600.0 } else { 60.0 };
        let number = |name: &str, default: f64, zero: bool| -> Result<f64> {
            let expected = if zero { "zero or a positive number" } else { "a positive number" };
            match env(name).filter(|v| !v.trim().is_empty()) {
                None => Ok(default),
                Some(text) => text
                    .trim()
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite() && (*v > 0.0 || zero && *v == 0.0))
                    .ok_or_else(|| Error::BadSetting(format!("{name}={text}: expected {expected}"))),
            }
        };
        Ok(SubmitBudget {
            flops: number("VKDIFF_SUBMIT_GFLOP", DEFAULT_SUBMIT_GFLOP, false)? * 1e9,
            dispatches: DISPATCHES_PER_SUBMIT,
            timeout: Duration::from_secs_f64(number("VKDIFF_SUBMIT_TIMEOUT", seconds, false)?),
            merge: Duration::from_secs_f64(number("VKDIFF_SUBMIT_MERGE", DEFAULT_MERGE_SECONDS, true)?),
        })
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
        let none = |_: &str| None;
        let budget = SubmitBudget::for_device(&gpu, &none).unwrap();
        assert_eq!((budget.flops, budget.dispatches, budget.timeout), (1e11, 256, Duration::from_secs(60)));
        assert_eq!(budget.merge, Duration::from_millis(100));
        let cpu = device(0, DeviceKind::Cpu, true);
        assert_eq!(SubmitBudget::for_device(&cpu, &none).unwrap().timeout, Duration::from_secs(600));
        let set = |name: &str| match name {
            "VKDIFF_SUBMIT_GFLOP" => Some("2.5".to_string()),
            "VKDIFF_SUBMIT_TIMEOUT" => Some("0.5".to_string()),
            "VKDIFF_SUBMIT_MERGE" => Some("0".to_string()),
            _ => None,
        };
        let budget = SubmitBudget::for_device(&gpu, &set).unwrap();
        assert_eq!((budget.flops, budget.timeout, budget.merge), (2.5e9, Duration::from_millis(500), Duration::ZERO));
        for bad in ["0", "-1", "fast", "inf"] {
            let env = |name: &str| (name == "VKDIFF_SUBMIT_GFLOP").then(|| bad.to_string());
            let err = SubmitBudget::for_device(&gpu, &env).unwrap_err().to_string();
            assert_eq!(err, format!("VKDIFF_SUBMIT_GFLOP={bad}: expected a positive number"));
        }
        for bad in ["-0.1", "soon", "NaN"] {
            let env = |name: &str| (name == "VKDIFF_SUBMIT_MERGE").then(|| bad.to_string());
            let err = SubmitBudget::for_device(&gpu, &env).unwrap_err().to_string();
            assert_eq!(err, format!("VKDIFF_SUBMIT_MERGE={bad}: expected zero or a positive number"));
        }
    }

    #[test]
    fn chunks_merge_while_their_times_stay_below_the_limit() {
        let ms = |v: &[u64]| v.iter().map(|&x| Duration::from_millis(x)).collect::<Vec<_>>();
        let budget = |merge: u64| SubmitBudget {
            flops: 1e11,
            dispatches: 256,
            timeout: Duration::from_secs(60),
            merge: Duration::from_millis(merge),
        };
        assert_eq!(budget(100).merged(&ms(&[30, 30, 30, 30, 30])), [3, 2]);
        // A chunk longer than the limit goes alone, and ends the submission before it.
        assert_eq!(budget(100).merged(&ms(&[10, 150, 10, 10])), [1, 1, 2]);
        assert_eq!(budget(0).merged(&ms(&[0, 0, 1])), [1, 1, 1]);
        assert_eq!(budget(100).merged(&[]), Vec::<usize>::new());
    }
}
