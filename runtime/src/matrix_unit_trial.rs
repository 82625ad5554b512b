//! Before a context first runs products on the device's matrix units, one product is timed
//! there and on the shared-memory tiled kernels, and the two results are compared. Drivers
//! list cooperative-matrix shapes their hardware does not have (Mesa lowers Intel's 8×8×16 to
//! ordinary arithmetic on GPUs without XMX, lavapipe emulates them all), and a driver's
//! matrix-unit path can be wrong where its tiled one is right; neither shows in what the
//! device reports. So the units are kept only where they agree with the tiled kernels and are
//! not clearly slower.

use crate::context::{Context, GemmFamily};
use crate::error::{Error, Result};
use crate::ops::linear;
use crate::recorder::Recorder;
use crate::tensor::{uniform_values, Dtype, Tensor};

/// The trial product: SDXL's 640-channel attention projections for one 512² image (1024 tokens), in f16.
const M: usize = 1024;
const N: usize = 640;
const K: usize = 640;
/// Products per family in the timed run.
const REPEATS: usize = 3;
/// The largest difference between the two families' results, relative to the largest result,
/// that still counts as agreement: both sum in f32 and round to f16 (2⁻¹¹ relative), in
/// different orders; a driver that garbles fragments misses by the results' own size.
pub const AGREEMENT: f32 = 1e-2;
/// How much faster the tiled kernels must be to displace the matrix units, so that a device
/// near a tie keeps one choice from run to run (and its images their bits).
pub const MARGIN: f64 = 1.25;

/// What `VKDIFF_COOPERATIVE` asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CooperativeSetting {
    /// Unset or `auto`: the matrix units where a variant fits and the trial keeps them.
    Trial,
    /// `1`: the matrix units wherever a variant fits, untried.
    Always,
    /// `0`: never (the tiled kernels).
    Never,
}

impl CooperativeSetting {
    pub fn from_env() -> Result<CooperativeSetting> {
        match std::env::var("VKDIFF_COOPERATIVE") {
            Err(_) => Ok(CooperativeSetting::Trial),
            Ok(value) => CooperativeSetting::parse(&value),
        }
    }

    /// `1`, `0` or `auto`, and the usual spellings of a switch (`true`/`false`, `yes`/`no`, `on`/`off`).
    pub fn parse(value: &str) -> Result<CooperativeSetting> {
        match value.trim().to_ascii_lowercase().as_str() {
            "auto" | "" => Ok(CooperativeSetting::Trial),
            "1" | "true" | "yes" | "on" => Ok(CooperativeSetting::Always),
            "0" | "false" | "no" | "off" => Ok(CooperativeSetting::Never),
            _ => Err(Error::BadSetting(format!(
                "VKDIFF_COOPERATIVE={value}: use 1 (the matrix units, untried), 0 (never) or auto (the default: \
                 tried against the tiled kernels as vkdiff starts)"
            ))),
        }
    }
}

/// What the trial found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MatrixUnitTrial {
    /// Time of one trial product on the matrix units and on the tiled kernels: device time from
    /// timestamps, or the host's clock around the run where the queue writes none.
    pub cooperative_ms: f64,
    pub tiled_ms: f64,
    /// Largest difference of the two results over the largest result.
    pub difference: f32,
    /// The kernels that ran the product in each family, where timestamps name them.
    pub cooperative_kernel: Option<&'static str>,
    pub tiled_kernel: Option<&'static str>,
}

impl MatrixUnitTrial {
    /// Whether the matrix units stay: they agree, and the tiled kernels are not [`MARGIN`] faster.
    pub fn keeps_matrix_units(&self) -> bool {
        self.agrees() && self.tiled_ms * MARGIN >= self.cooperative_ms
    }

    /// Whether the two results agree ([`AGREEMENT`]); a NaN difference never does.
    pub fn agrees(&self) -> bool {
        self.difference <= AGREEMENT
    }

    /// One line on what was chosen and why.
    pub fn summary(&self, device: &str) -> String {
        let times = format!(
            "a {M}×{N}×{K} f16 product took {:.3} ms on the matrix units, {:.3} ms on the tiled kernels",
            self.cooperative_ms, self.tiled_ms
        );
        if !self.agrees() {
            format!(
                "`{device}`: the matrix units' product differs from the tiled kernels' by {:.2e} of its size ({times}): \
                 using the tiled kernels (VKDIFF_COOPERATIVE=1 forces the matrix units)",
                self.difference
            )
        } else if self.keeps_matrix_units() {
            format!("`{device}`: {times}, results agree: using the matrix units")
        } else {
            format!(
                "`{device}`: {times}, results agree: using the tiled kernels (VKDIFF_COOPERATIVE=1 forces the matrix \
                 units)"
            )
        }
    }
}

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
    let before = ctx.gemm_family();
    let outcome = timed_products(ctx, clock);
    ctx.set_gemm_family(before);
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
        ctx.set_gemm_family(family);
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

/// max |a − b| / max |b|; NaN where the lengths differ or either holds a NaN or an infinity
/// (never agreement).
pub fn relative_difference(a: &[f32], b: &[f32]) -> f32 {
    if a.len() != b.len() || a.iter().chain(b).any(|v| !v.is_finite()) {
        return f32::NAN;
    }
    let scale = b.iter().fold(0f32, |m, v| m.max(v.abs()));
    a.iter().zip(b).fold(0f32, |m, (x, y)| m.max((x - y).abs())) / scale
}

#[cfg(test)]
mod tests {
    use super::*;

    fn trial(cooperative_ms: f64, tiled_ms: f64, difference: f32) -> MatrixUnitTrial {
        MatrixUnitTrial { cooperative_ms, tiled_ms, difference, cooperative_kernel: None, tiled_kernel: None }
    }

    #[test]
    fn the_units_stay_unless_they_disagree_or_the_tiles_are_clearly_faster() {
        assert!(trial(1.0, 4.0, 1e-3).keeps_matrix_units());
        assert!(trial(1.2, 1.0, 1e-3).keeps_matrix_units(), "within the margin");
        assert!(!trial(1.3, 1.0, 1e-3).keeps_matrix_units(), "tiles a quarter faster");
        assert!(!trial(1.0, 4.0, 0.5).keeps_matrix_units(), "garbled");
        assert!(!trial(1.0, 4.0, f32::NAN).keeps_matrix_units(), "NaN results");
    }

    #[test]
    fn differences_are_relative_and_nan_is_never_agreement() {
        assert_eq!(relative_difference(&[1.0, 2.0], &[1.0, 4.0]), 0.5);
        assert!(relative_difference(&[f32::NAN, 0.0], &[1.0, 1.0]).is_nan());
        assert!(relative_difference(&[1.0, 1.0], &[f32::INFINITY, 1.0]).is_nan());
        assert!(relative_difference(&[1.0], &[1.0, 1.0]).is_nan());
    }

    #[test]
    fn the_summary_names_the_choice() {
        assert!(trial(1.0, 4.0, 1e-3).summary("gpu").ends_with("using the matrix units"));
        assert!(trial(1.0, 4.0, 0.5).summary("gpu").contains("differs from the tiled kernels' by 5.00e-1"));
        assert!(trial(4.0, 1.0, 1e-3).summary("gpu").contains("using the tiled kernels"));
    }

    #[test]
    fn the_setting_takes_the_spellings_of_a_switch() {
        for (value, setting) in [
            ("auto", CooperativeSetting::Trial),
            ("1", CooperativeSetting::Always),
            ("True", CooperativeSetting::Always),
            ("on", CooperativeSetting::Always),
            ("0", CooperativeSetting::Never),
            ("no", CooperativeSetting::Never),
            ("OFF", CooperativeSetting::Never),
        ] {
            assert_eq!(CooperativeSetting::parse(value).unwrap(), setting, "{value}");
        }
        let err = CooperativeSetting::parse("2").unwrap_err().to_string();
        assert!(err.contains("VKDIFF_COOPERATIVE=2: use 1"), "{err}");
    }
}
