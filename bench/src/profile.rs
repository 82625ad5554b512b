//! `--profile`: device time per kernel over a profiled run, largest first.

use vkdiff_runtime::Timing;

/// One kernel's share of a profiled run.
#[derive(serde::Serialize)]
pub(crate) struct KernelTime {
    kernel: &'static str,
    dispatches: usize,
    ms: f64,
}

/// The dispatches' times summed per kernel, largest first.
pub(crate) fn by_kernel(timings: impl IntoIterator<Item = Timing>) -> Vec<KernelTime> {
    let mut by_kernel: Vec<KernelTime> = Vec::new();
    for t in timings {
        match by_kernel.iter_mut().find(|k| k.kernel == t.kernel) {
            Some(k) => (k.dispatches, k.ms) = (k.dispatches + 1, k.ms + t.nanos / 1e6),
            None => by_kernel.push(KernelTime { kernel: t.kernel, dispatches: 1, ms: t.nanos / 1e6 }),
        }
    }
    by_kernel.sort_by(|a, b| b.ms.total_cmp(&a.ms));
    by_kernel
}

/// The profile as indented lines under a summary, empty without `--profile`.
pub(crate) fn lines(profile: &[KernelTime]) -> String {
    let total: f64 = profile.iter().map(|k| k.ms).sum();
    profile
        .iter()
        .map(|k| {
            format!(
                "\n  {:<22} {:>5} dispatches {:>9.2} ms {:>5.1} %",
                k.kernel,
                k.dispatches,
                k.ms,
                100.0 * k.ms / total
            )
        })
        .collect()
}
