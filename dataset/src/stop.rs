//! A clean stop asked by a signal: Ctrl-C (SIGINT), or the SIGTERM a scheduler sends before it
//! kills a preempted Slurm task or an evicted pod. The loop finishes the images in hand, the
//! writer writes them, and the run ends with [`crate::Error::Interrupted`] (exit code 4: the
//! same command resumes). A second signal stops the process at once, as the signal would have.

use std::sync::atomic::{AtomicBool, Ordering};

static STOP: AtomicBool = AtomicBool::new(false);

const NOTE: &[u8] =
    b"\nstopping once the images in hand are written; the same command resumes (signal again to stop now)\n";

extern "C" fn on_signal(signal: libc::c_int) {
    if STOP.swap(true, Ordering::SeqCst) {
        // SAFETY: signal() and raise() are async-signal-safe; the default action ends the process.
        unsafe {
            libc::signal(signal, libc::SIG_DFL);
            libc::raise(signal);
        }
        return;
    }
    // SAFETY: write() is async-signal-safe; the buffer is static.
    unsafe { libc::write(libc::STDERR_FILENO, NOTE.as_ptr().cast(), NOTE.len()) };
}

/// From now on SIGINT and SIGTERM ask the dataset loops to stop cleanly.
pub fn stop_on_signals() {
    for signal in [libc::SIGINT, libc::SIGTERM] {
        // SAFETY: the handler only touches an atomic and calls async-signal-safe functions.
        unsafe { libc::signal(signal, on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t) };
    }
}

/// Whether a signal asked the run to stop.
pub fn stop_requested() -> bool {
    STOP.load(Ordering::SeqCst)
}

/// The error a loop stops with once `done` of the shard's `total` images are made.
pub(crate) fn interrupted(done: u64, total: u64) -> crate::Error {
    crate::Error::Interrupted(format!(
        "stopped by a signal with {done} of this shard's {total} images done; run the same command to resume"
    ))
}
