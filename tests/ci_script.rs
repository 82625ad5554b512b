//! The CI script's own check (`.ci/count-tests`): a pass that runs no test fails, as does one
//! a `--test` target of which runs none (an ignored test did not run) or one of whose libtest
//! filters selects none; `.ci/run` counts every pass with it, given the pass's arguments.

use std::path::Path;
use std::process::Command;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Runs `.ci/count-tests` on a log with a pass's `cargo test` arguments: (success, its line).
fn count(log: &str, cargo_args: &[&str]) -> (bool, String) {
    // A folder per call: the tests run in parallel.
    static CALLS: AtomicUsize = AtomicUsize::new(0);
    let dir = vkdiff_testkit::scratch(&format!("ci-count-{}", CALLS.fetch_add(1, Ordering::Relaxed)));
    let path = dir.join("pass.log");
    std::fs::write(&path, log).unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = Command::new("bash").arg(root.join(".ci/count-tests")).arg(&path).args(cargo_args).output().unwrap();
    (out.status.success(), String::from_utf8_lossy(&out.stdout).trim().to_string())
}

/// Two test binaries' output as cargo prints it (the `Running` lines come from its stderr).
const TWO_TARGETS: &str = "   Compiling vkdiff v0.2.0 (/work)\n\
    \x20    Running tests/kernels/main.rs (target/release/deps/kernels-0123456789abcdef)\n\n\
    running 3 tests\ntest gemm::linear_layer_shapes ... ok\ntest runtime::views ... ok\n\
    test conv::conv1x1 ... FAILED\n\ntest result: FAILED. 2 passed; 1 failed\n\n\
    \x20    Running tests/batch.rs (/tmp/target/release/deps/batch-fedcba9876543210)\n\n\
    running 2 tests\ntest split_into_bands ... ignored, needs the GPU paths\ntest gemm_batch ... ignored\n\n\
    test result: ok. 0 passed; 0 failed; 2 ignored\n";

#[test]
fn a_pass_or_filter_that_selects_no_test_fails() {
    let kernels = ["--workspace", "--test", "kernels", "--"];
    let with = |filters: &[&'static str]| [&kernels[..], filters].concat();
    let line = "3 tests (kernels 3, batch 0 (+2 ignored)), 2 ignored";
    assert_eq!(count(TWO_TARGETS, &with(&["gemm", "runtime::"])), (true, format!("{line}; 'gemm' 1; 'runtime::' 1")));
    // The dead filter of 2026-11-28: `into_bands` matched nothing in its binaries.
    assert_eq!(
        count(TWO_TARGETS, &with(&["gemm", "into_bands"])),
        (false, format!("{line}; 'gemm' 1; 'into_bands' 0"))
    );
    // An ignored test matches its filter but does not run.
    assert!(!count(TWO_TARGETS, &with(&["split_into_bands"])).0);
    assert_eq!(count("running 0 tests\ntest result: ok. 0 passed\n", &[]), (false, "0 tests".into()));
}

#[test]
fn a_named_target_that_runs_no_test_fails() {
    assert!(count(TWO_TARGETS, &["--workspace", "--test", "kernels"]).0);
    // Every test of `batch` ignored, and `memory_plan` never ran: both count as nothing run.
    let line = "3 tests (kernels 3, batch 0 (+2 ignored)), 2 ignored";
    assert_eq!(count(TWO_TARGETS, &["--workspace", "--test", "kernels", "--test", "batch"]), (false, line.into()));
    let absent = count(TWO_TARGETS, &["--workspace", "--test=kernels", "--test", "memory_plan"]);
    assert_eq!(absent, (false, "3 tests (kernels 3, batch 0 (+2 ignored), memory_plan 0), 2 ignored".into()));
}

#[test]
fn every_pass_is_counted_with_its_arguments() {
    let script = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join(".ci/run")).unwrap();
    assert!(script.contains(".ci/count-tests \"$out\" \"$@\""), "every pass is counted with its cargo arguments");
}
