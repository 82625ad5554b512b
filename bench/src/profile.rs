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

/// One shape as `VKDIFF_TUNE=1` found it: each candidate's kernels and fastest milliseconds
/// (null where it failed, disagreed or was not timed, its note in `kernels`), and which it took.
#[derive(serde::Serialize)]
pub(crate) struct TunedRow {
    op: String,
    candidates: Vec<(String, Option<f64>)>,
    chosen: usize,
}

/// What the context's tuning chose, shape by shape (empty where it did not tune).
pub(crate) fn tuned(ctx: &vkdiff_runtime::Context) -> Vec<TunedRow> {
    let row = |s: vkdiff_runtime::TunedShape| TunedRow {
        op: s.op,
        candidates: s.timed.into_iter().map(|(k, ms)| (k, Some(ms).filter(|ms| ms.is_finite()))).collect(),
        chosen: s.chosen,
    };
    ctx.tuned_shapes().into_iter().map(row).collect()
}

/// The tuned shapes as indented lines, the chosen candidate marked with `*`.
pub(crate) fn tuned_lines(rows: &[TunedRow]) -> String {
    let mut out = String::new();
    if !rows.is_empty() {
        out += &format!("\n  VKDIFF_TUNE: {} shapes had kernels to choose between", rows.len());
    }
    for row in rows {
        out += &format!("\n  {}", row.op);
        for (i, (kernels, ms)) in row.candidates.iter().enumerate() {
            let mark = if i == row.chosen { '*' } else { ' ' };
            let ms = ms.map_or("—".to_string(), |ms| format!("{ms:.3} ms"));
            out += &format!("\n    {mark} {ms:>11}  {kernels}");
        }
    }
    out
}
