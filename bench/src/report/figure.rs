//! One figure of a report: what was timed, its runs' median and spread, its memory and first
//! run, and the reference beside it; the rows `bench report` prints and `bench compare` lines up.

use serde::{Deserialize, Serialize};

/// Seconds of repeated runs: the median, the fastest and slowest (MLPerf's and llama-bench's
/// convention: a median after a warm-up, with its spread).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Runs {
    pub median: f64,
    pub min: f64,
    pub max: f64,
    pub count: usize,
}

impl Runs {
    /// None for no values, or any that is not a finite number (never dropped quietly).
    pub fn of(values: &[f64]) -> Option<Runs> {
        if values.is_empty() || !values.iter().all(|x| x.is_finite()) {
            return None;
        }
        let mut v = values.to_vec();
        v.sort_by(f64::total_cmp);
        let n = v.len();
        let median = if n % 2 == 1 { v[n / 2] } else { (v[n / 2 - 1] + v[n / 2]) / 2.0 };
        Some(Runs { median, min: v[0], max: v[n - 1], count: n })
    }

    /// The spread as a share of the median: (max − min) / median.
    pub fn spread(&self) -> f64 {
        if self.median > 0.0 {
            (self.max - self.min) / self.median
        } else {
            0.0
        }
    }
}

/// What ran beside vkdiff in the same invocation, or why nothing did.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(untagged)]
pub enum Reference {
    Measured {
        /// In the figure's unit.
        value: f64,
        /// Who and where: "diffusers 0.42.1, torch 2.15, CPU float32, 2 threads".
        what: String,
    },
    Missing {
        /// Why no reference value stands here.
        why: String,
    },
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Figure {
    /// Stable across versions of the suite: `bench compare` matches rows by it.
    pub id: String,
    /// `image`, `ablation`, `unet`, `vae` or `kernels`.
    pub group: String,
    /// What it is, for people: "the paper's image, 1024², 30 steps".
    pub label: String,
    /// `s`, `ms` or `TFLOP/s`.
    pub unit: String,
    /// Whether a larger value is better (rates) or worse (times).
    pub higher_is_better: bool,
    pub runs: Runs,
    /// The first run, warm-up included: kernels compiled and memory first allocated.
    pub first_run: Option<f64>,
    /// Peak device memory while this figure ran, MiB.
    pub peak_mib: Option<f64>,
    /// Parts of the value (an image's stages), in its unit.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub parts: Vec<(String, f64)>,
    /// How the value was obtained where it is not simply timed (steps extrapolated, …).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
    /// The share of the device's f16 matrix peak (rates of products on known GPUs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub peak_share: Option<f64>,
    pub reference: Reference,
}

/// The id suffix of a figure repeated against the compiled PyTorch model: the same vkdiff runs,
/// another reference.
pub const COMPILED: &str = ".compiled";

impl Figure {
    /// Whether this row repeats another's vkdiff runs against the compiled reference
    /// (`bench compare` lines up vkdiff's own figures, so it leaves these out).
    pub fn is_compiled_twin(&self) -> bool {
        self.id.ends_with(COMPILED)
    }

    /// How much faster vkdiff is than the reference (above 1: faster), where one was measured.
    pub fn speedup(&self) -> Option<f64> {
        match self.reference {
            Reference::Measured { value, .. } if value > 0.0 && self.runs.median > 0.0 => {
                Some(if self.higher_is_better { self.runs.median / value } else { value / self.runs.median })
            }
            _ => None,
        }
    }
}

/// A value in its unit with sensible digits: 0.153 s, 14.2 ms, 169 TFLOP/s (below 1 TFLOP/s,
/// in GFLOP/s: 25.3 GFLOP/s).
pub fn show(value: f64, unit: &str) -> String {
    if unit == "TFLOP/s" && value < 1.0 {
        return show(value * 1e3, "GFLOP/s");
    }
    let digits = if value >= 100.0 {
        0
    } else if value >= 10.0 {
        1
    } else if value >= 1.0 {
        2
    } else {
        3
    };
    format!("{value:.digits$} {unit}")
}

/// A UNet figure in ms of one run, `id` its id and label, for the report's tests.
#[cfg(test)]
pub(crate) fn test_figure(id: &str, median: f64, reference: Reference) -> Figure {
    Figure {
        id: id.into(),
        group: "unet".into(),
        label: id.into(),
        unit: "ms".into(),
        higher_is_better: false,
        runs: Runs::of(&[median]).unwrap(),
        first_run: None,
        peak_mib: None,
        parts: vec![],
        note: None,
        peak_share: None,
        reference,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_median_of_odd_and_even_counts_and_the_spread() {
        let r = Runs::of(&[3.0, 1.0, 2.0]).unwrap();
        assert_eq!((r.median, r.min, r.max, r.count), (2.0, 1.0, 3.0, 3));
        assert_eq!(Runs::of(&[4.0, 1.0, 2.0, 3.0]).unwrap().median, 2.5);
        assert!((r.spread() - 1.0).abs() < 1e-12);
        // A zero median has no share to spread over (not an infinity in the table).
        assert_eq!(Runs::of(&[0.0, 0.0, 5.0]).unwrap().spread(), 0.0);
        assert_eq!(Runs::of(&[f64::NAN]), None);
        assert_eq!(Runs::of(&[1.0, f64::INFINITY]), None);
    }

    #[test]
    fn speedups_read_the_same_way_for_times_and_rates() {
        let mut f = test_figure("x", 100.0, Reference::Measured { value: 50.0, what: "diffusers".into() });
        assert_eq!(f.speedup(), Some(0.5));
        f.higher_is_better = true;
        assert_eq!(f.speedup(), Some(2.0));
        f.reference = Reference::Missing { why: "no torch".into() };
        assert_eq!(f.speedup(), None);
        assert_eq!(
            (show(0.1534, "s"), show(14.23, "ms"), show(169.4, "TFLOP/s")),
            ("0.153 s".into(), "14.2 ms".into(), "169 TFLOP/s".into())
        );
        assert_eq!(show(0.0253, "TFLOP/s"), "25.3 GFLOP/s");
    }
}
