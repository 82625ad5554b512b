//! A one-line progress bar on stderr with rate and time left; plain lines when stderr is not a
//! terminal (logs, CI), so scripts still see progress.

use std::io::{IsTerminal, Write};
use std::time::Instant;

pub struct Progress {
    label: &'static str,
    unit: &'static str,
    start: Instant,
    tty: bool,
}

impl Progress {
    pub fn new(label: &'static str, unit: &'static str) -> Progress {
        Progress { label, unit, start: Instant::now(), tty: std::io::stderr().is_terminal() }
    }

    /// `done` of `total` finished.
    pub fn update(&self, done: usize, total: usize) {
        let secs = self.start.elapsed().as_secs_f64();
        let rate = done as f64 / secs.max(1e-9);
        let left = (total - done) as f64 / rate.max(1e-9);
        let width = 30;
        let filled = width * done / total.max(1);
        let bar: String = "#".repeat(filled) + &"-".repeat(width - filled);
        let speed = if rate >= 1.0 { format!("{rate:.2} {}/s", self.unit) } else { format!("{:.2} s/{}", 1.0 / rate.max(1e-9), self.unit) };
        let line = format!("{} [{bar}] {done}/{total}  {speed}  {left:.0} s left", self.label);
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
