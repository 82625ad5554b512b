//! A one-line progress bar on stderr with rate and time left; plain lines when stderr is not a
//! terminal (logs, CI), so scripts still see progress.

use std::io::{IsTerminal, Write};
use std::time::Instant;

pub struct Progress {
    label: &'static str,
    unit: &'static str,
    start: Instant,
    tty: bool,
    /// Done before this process started (a resumed run): not counted in the rate.
    before: usize,
}

impl Progress {
    pub fn new(label: &'static str, unit: &'static str) -> Progress {
        Progress { label, unit, start: Instant::now(), tty: std::io::stderr().is_terminal(), before: 0 }
    }

    /// A bar whose first `before` units were done by an earlier run.
    pub fn resuming(label: &'static str, unit: &'static str, before: usize) -> Progress {
        Progress { before, ..Progress::new(label, unit) }
    }

    /// `done` of `total` finished.
    pub fn update(&self, done: usize, total: usize) {
        self.show(done, total, "", true);
    }

    /// `done` of `total` finished, with a `note` on the work in hand. Without a terminal only
    /// a change of `done` prints a line (`new_unit`), so logs get one line per unit.
    pub fn show(&self, done: usize, total: usize, note: &str, new_unit: bool) {
        if !self.tty && !new_unit {
            return;
        }
        let secs = self.start.elapsed().as_secs_f64();
        let rate = done.saturating_sub(self.before) as f64 / secs.max(1e-9);
        let left = (total - done) as f64 / rate.max(1e-9);
        let width = 30;
        let filled = width * done / total.max(1);
        let bar: String = "#".repeat(filled) + &"-".repeat(width - filled);
        let speed = match rate {
            r if r >= 1.0 => format!("{r:.2} {}/s", self.unit),
            r if r > 0.0 => format!("{:.2} s/{}", 1.0 / r, self.unit),
            _ => String::new(),
        };
        let left = if rate > 0.0 { format!("{}left", duration(left)) } else { "…".into() };
        let line = format!("{} [{bar}] {done}/{total}  {speed}  {left}{note}", self.label);
        let mut err = std::io::stderr().lock();
        if self.tty {
            let _ = write!(err, "\r{line}\x1b[K");
            if done == total {
                let _ = writeln!(err);
            }
        } else {
            let _ = writeln!(err, "{line}");
        }
    }
}

/// `1 h 02 min `, `3 min 05 s `, `12 s `.
fn duration(secs: f64) -> String {
    let s = secs.round() as u64;
    match s {
        0..60 => format!("{s} s "),
        60..3600 => format!("{} min {:02} s ", s / 60, s % 60),
        _ => format!("{} h {:02} min ", s / 3600, s % 3600 / 60),
    }
}
