//! Paths of the repository's fixtures (written by the scripts in `tools/`) and scratch space.

use std::path::{Path, PathBuf};
use std::sync::Once;

/// `path` relative to the repository root: the one the tests were built in, or `VKDIFF_REPO`
/// (tools/gpu-check.sh runs test binaries built elsewhere against the fixtures its kit carries).
pub fn repo(path: &str) -> PathBuf {
    let root = std::env::var_os("VKDIFF_REPO")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(".."));
    root.join(path)
}

/// `tests/fixtures/<path>`.
pub fn fixture(path: &str) -> PathBuf {
    repo("tests/fixtures").join(path)
}

const SCRATCH_PREFIX: &str = "vkdiff-test-";

/// An empty folder of this process for one test's files (`name` tells tests apart), under the
/// process's own folder in the temporary directory. A test process has no hook at its end, so
/// the first call removes the folders of earlier test processes that have ended: the last
/// run's files stay for a look after a failure, and no run's pile up.
pub fn scratch(name: &str) -> PathBuf {
    static SWEEP: Once = Once::new();
    let tmp = std::env::temp_dir();
    SWEEP.call_once(|| sweep_ended(&tmp));
    let dir = tmp.join(format!("{SCRATCH_PREFIX}{}", std::process::id())).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Removes `vkdiff-test-<pid>` folders (and the `vkdiff-test-<pid>-<name>` ones older test
/// builds made) whose process has ended, where the system says which processes run (`/proc`).
fn sweep_ended(tmp: &Path) {
    let processes = Path::new("/proc/self");
    if !processes.exists() {
        return;
    }
    let Ok(entries) = std::fs::read_dir(tmp) else { return };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(rest) = name.to_str().and_then(|n| n.strip_prefix(SCRATCH_PREFIX)) else { continue };
        let pid = rest.split('-').next().unwrap_or_default();
        if !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit()) && !Path::new("/proc").join(pid).exists() {
            let _ = std::fs::remove_dir_all(entry.path());
        }
    }
}
