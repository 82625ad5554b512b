//! The one rule for what a denoising step costs, on vkdiff's side and on every reference's: the
//! median of the timed steps after the first. The first step holds one-time work the others do
//! not repeat (a recording's first replay, memory first touched; in diffusers, the call's own
//! preparation before its first step ends), and the median keeps one slow step from moving the
//! rate. Scripts print each step's seconds; the rule is applied here only.

use crate::report::Runs;

/// The timed steps after the first, whose median is the step's time.
pub fn steps_after_first(steps: &[f64]) -> Result<Runs, String> {
    let after = steps.get(1..).filter(|after| !after.is_empty()).ok_or_else(|| {
        format!("{} timed step(s): a step's time leaves out the first, so it needs at least 2", steps.len())
    })?;
    Runs::of(after).ok_or_else(|| format!("a step time that is not a number: {steps:?}"))
}

/// An image's `seconds`, in which the timed `steps` ran, with the steps up to `total_steps` that
/// did not run counted at the step's time.
pub fn with_untimed_steps(seconds: f64, steps: &[f64], total_steps: usize) -> Result<f64, String> {
    let untimed = total_steps
        .checked_sub(steps.len())
        .ok_or_else(|| format!("{} steps timed of an image of {total_steps}", steps.len()))?;
    if untimed == 0 {
        return Ok(seconds);
    }
    Ok(seconds + untimed as f64 * steps_after_first(steps)?.median)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_step_is_the_median_of_the_steps_after_the_first() {
        // The slow first step (kernels, memory) and one slow later step move nothing.
        let runs = steps_after_first(&[9.0, 1.0, 5.0, 2.0]).unwrap();
        assert_eq!((runs.median, runs.min, runs.max, runs.count), (2.0, 1.0, 5.0, 3));
        assert_eq!(steps_after_first(&[9.0, 1.5]).unwrap().median, 1.5);
        let why = steps_after_first(&[9.0]).unwrap_err();
        assert!(why.contains("1 timed step(s)") && why.contains("at least 2"), "{why}");
        assert!(steps_after_first(&[]).is_err());
        assert!(steps_after_first(&[1.0, f64::NAN]).is_err(), "a bad time is an error, not dropped");
    }

    #[test]
    fn untimed_steps_count_at_the_step_rate() {
        // 2 of 30 steps timed: 28 more at the second step's 1.5 s (not the mean, 2.75 s).
        assert_eq!(with_untimed_steps(7.0, &[4.0, 1.5], 30).unwrap(), 7.0 + 28.0 * 1.5);
        // Every step timed: the image as measured, whatever its first step.
        assert_eq!(with_untimed_steps(7.0, &[4.0], 1).unwrap(), 7.0);
        assert_eq!(with_untimed_steps(7.0, &[4.0, 1.0, 1.0], 3).unwrap(), 7.0);
        assert!(with_untimed_steps(7.0, &[4.0, 1.0, 1.0], 2).unwrap_err().contains("3 steps timed of an image of 2"));
        assert!(with_untimed_steps(7.0, &[4.0], 30).is_err(), "one timed step gives no rate");
    }
}
