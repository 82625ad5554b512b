//! The CI script's own check (`.ci/count-tests`): a pass whose run, or any of whose libtest
//! filters, selects no test fails, and `.ci/run` counts every pass with it.

use std::path::Path;
use std::process::Command;

fn count(log: &str, filters: &[&str]) -> (bool, String) {
    let dir = vkdiff_testkit::scratch("ci-count");
    let path = dir.join("pass.log");
    std::fs::write(&path, log).unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = Command::new("bash").arg(root.join(".ci/count-tests")).arg(&path).args(filters).output().unwrap();
    (out.status.success(), String::from_utf8_lossy(&out.stdout).trim().to_string())
}

#[test]
fn a_pass_or_filter_that_selects_no_test_fails() {
    let log = "running 3 tests\ntest gemm::linear_layer_shapes ... ok\ntest runtime::views ... ok\n\
               test conv::conv1x1 ... FAILED\ntest result: FAILED. 2 passed; 1 failed\n";
    assert_eq!(count(log, &["gemm", "runtime::"]), (true, "3 tests; 'gemm' 1; 'runtime::' 1".into()));
    // The dead filter of 2026-11-28: `into_bands` matched nothing in its binaries.
    assert_eq!(count(log, &["gemm", "into_bands"]), (false, "3 tests; 'gemm' 1; 'into_bands' 0".into()));
    assert_eq!(count("running 0 tests\ntest result: ok. 0 passed\n", &[]), (false, "0 tests".into()));
    let script = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join(".ci/run")).unwrap();
    assert!(script.contains(".ci/count-tests \"$out\" \"${filters[@]}\""), "every pass is counted");
}
