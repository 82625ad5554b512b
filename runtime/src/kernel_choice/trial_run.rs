//! The matrix units' trial run: one product timed on the units and on the tiled kernels
//! ([`crate::MatrixUnitTrial`] says what it found).

use crate::context::Context;
use crate::error::{Error, Result};
use crate::kernel_choice::plan::GemmFamily;
use crate::kernel_choice::trial::{relative_difference, MatrixUnitTrial, K, M, N};
use crate::ops::linear;
use crate::recorder::Recorder;
use crate::tensor::{uniform_values, Dtype, Tensor};

/// Products per family in the timed run.
const REPEATS: usize = 3;
/// How the trial times its products.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TrialClock {
    /// The device's timestamps around each product.
    Timestamps,
    /// The host's clock around the run: where the queue writes no timestamps.
    Host,
}

/// Runs the trial on `ctx`'s matrix units, whose variant must fit, timed by the device where it
/// writes timestamps; leaves the context's family as found.
pub fn run_trial(ctx: &Context) -> Result<MatrixUnitTrial> {
    run_trial_timed_by(ctx, if ctx.info().timestamps() { TrialClock::Timestamps } else { TrialClock::Host })
}

/// [`run_trial`] timed by `clock`.
pub fn run_trial_timed_by(ctx: &Context, clock: TrialClock) -> Result<MatrixUnitTrial> {
    if ctx.info().cooperative_variant().is_none() {
        return Err(Error::Shape(format!("matrix-unit trial: `{}` has no variant to try", ctx.info().name)));
    }
    let before = ctx.choices().gemm_family;
    let outcome = timed_products(ctx, clock);
    ctx.choose(|c| c.gemm_family = before);
    let (cooperative, tiled) = outcome?;
    Ok(MatrixUnitTrial {
        cooperative_ms: cooperative.ms,
        tiled_ms: tiled.ms,
        difference: relative_difference(&cooperative.result, &tiled.result),
        cooperative_kernel: cooperative.kernel,
        tiled_kernel: tiled.kernel,
    })
}

/// One family's time per product (from the second of two runs: the first may compile), the
/// kernel that ran it and its result.
struct Timed {
    ms: f64,
    kernel: Option<&'static str>,
    result: Vec<f32>,
}

fn timed_products(ctx: &Context, clock: TrialClock) -> Result<(Timed, Timed)> {
    let x = ctx.upload(&[M, K], Dtype::F16, &uniform_values(M * K, 1))?;
    let w = ctx.upload(&[N, K], Dtype::F16, &uniform_values(N * K, 2))?;
    let run = |family: GemmFamily| -> Result<Timed> {
        ctx.choose(|c| c.gemm_family = family);
        let out = ctx.zeros(&[M, N], Dtype::F16)?;
        let stamps = clock == TrialClock::Timestamps;
        let recording = products(ctx, &x, &w, &out, stamps)?;
        recording.run()?;
        let (nanos, kernel) = if stamps {
            let timings = recording.run_profiled()?;
            (timings.iter().map(|t| t.nanos).sum(), timings.first().map(|t| t.kernel))
        } else {
            let start = std::time::Instant::now();
            recording.run()?;
            (start.elapsed().as_nanos() as f64, None)
        };
        Ok(Timed { ms: nanos / REPEATS as f64 / 1e6, kernel, result: out.download()? })
    };
    Ok((run(GemmFamily::Cooperative)?, run(GemmFamily::Tiled)?))
}

fn products(ctx: &Context, x: &Tensor, w: &Tensor, out: &Tensor, timed: bool) -> Result<crate::recording::Recording> {
    let mut rec = Recorder::new(ctx, timed)?;
    for _ in 0..REPEATS {
        linear(&mut rec, x, w, None, out)?;
    }
    rec.finish()
}
