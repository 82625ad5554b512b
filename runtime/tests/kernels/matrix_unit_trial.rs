//! The trial that decides, as a context starts, whether the matrix units run its products.

use vkdiff_runtime::{run_trial, run_trial_timed_by, GemmFamily, TrialClock};
use vkdiff_testkit::*;

#[test]
fn the_matrix_unit_trial_runs_both_families_and_they_agree() {
    let ctx = ctx_with(GemmFamily::Cooperative);
    if ctx.info().cooperative_variant().is_none() {
        let err = run_trial(&ctx).unwrap_err().to_string();
        assert!(err.contains("has no variant to try"), "{err}");
        return;
    }
    // lavapipe writes timestamps; the host's clock serves queues that write none.
    for (clock, named) in
        [(TrialClock::Timestamps, (Some("gemm_coop"), Some("gemm_tiled_v4"))), (TrialClock::Host, (None, None))]
    {
        let trial = run_trial_timed_by(&ctx, clock).unwrap();
        assert_eq!((trial.cooperative_kernel, trial.tiled_kernel), named, "{clock:?}: {trial:?}");
        assert!(trial.cooperative_ms > 0.0 && trial.tiled_ms > 0.0, "{clock:?}: {trial:?}");
        // Both sum in f32 and round to f16: a garbled fragment would miss by the results' size.
        assert!(trial.difference < 2e-3, "{clock:?}: {trial:?}");
        assert_eq!(ctx.choices().gemm_family, GemmFamily::Cooperative, "the trial leaves the family as it found it");
    }
}

/// A context whose device has matrix units, on the GPU paths with `VKDIFF_COOPERATIVE` unset (the
/// CI pass of the trial at each start, on Mesa 26.1), has run the trial as it started; and any new
/// context, trial or not, starts holding no live, idle or peak bytes of its own.
#[test]
fn a_fresh_context_ran_its_trial_and_holds_nothing() {
    let ctx = private_ctx();
    let trial_due = ctx.choices().gpu_paths
        && ctx.info().cooperative_variant().is_some()
        && std::env::var("VKDIFF_COOPERATIVE").map_or(true, |v| v.is_empty() || v == "auto");
    if trial_due {
        let trial = ctx.matrix_unit_trial().expect("the matrix units' trial ran as the context started");
        assert!(trial.cooperative_ms > 0.0 && trial.tiled_ms > 0.0, "{trial:?}");
    }
    assert_eq!((ctx.live_bytes(), ctx.idle_bytes(), ctx.peak_bytes()), (0, 0, 0), "trial due: {trial_due}");
}
