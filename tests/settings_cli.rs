//! `VKDIFF_*` settings at the edge: each is parsed once, by one grammar, before any work; a value
//! its setting does not take exits 2 with one line naming the variable and what it takes, for
//! every command (those that open no device too); a switch takes every spelling of one; the
//! runtime itself reads no environment, and no crate below `main` reads the process's.

mod cli;

use cli::{scratch, vkdiff_with};

/// Each runtime variable with a value it refuses, and a word of what it takes.
const REFUSED: [(&str, &str, &str); 20] = [
    ("VKDIFF_VULKAN_API", "1.1", "1.2 or 1.3"),
    ("VKDIFF_VALIDATE", "please", "1 or 0"),
    ("VKDIFF_GPU_PATHS", "gpu", "1 or 0"),
    ("VKDIFF_QUICK_COMPILE", "fast", "1 or 0"),
    ("VKDIFF_PIPELINE_STATS", "all", "1 or 0"),
    ("VKDIFF_COOPERATIVE", "sometimes", "1 or 0"),
    ("VKDIFF_FRAGMENT", "16x8x16", "one of the shapes vkdiff builds"),
    ("VKDIFF_MATRIX_TILE", "128", "128x64"),
    ("VKDIFF_ATTENTION", "flash", "cm2"),
    ("VKDIFF_LINEAR", "fast", "cm2"),
    ("VKDIFF_CONV", "winograd", "cm2"),
    ("VKDIFF_TUNE", "fast", "1 or 0"),
    ("VKDIFF_SUBMIT_GFLOP", "0", "a positive number of GFLOP"),
    ("VKDIFF_SUBMIT_TIMEOUT", "soon", "a positive number of seconds"),
    ("VKDIFF_SUBMIT_MERGE", "-1", "zero or a positive number of seconds"),
    ("VKDIFF_MEMORY_BUDGET", "lots", "a size such as 8G"),
    ("VKDIFF_BUFFER_CACHE", "maybe", "1 or 0"),
    ("VKDIFF_WINOGRAD", "maybe", "1 or 0"),
    ("VKDIFF_DEVICE", "the-fast-one", "an index, a UUID or a PCI address"),
    ("VKDIFF_REQUIRE_GPU", "2", "1 or 0"),
];

#[test]
fn a_value_no_setting_takes_exits_2_naming_the_variable_before_any_work() {
    let dir = scratch("settings-refused");
    let out = dir.join("scene");
    let model = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/pipeline/tiny-sdxl");
    let png = dir.join("x.png");
    let gen =
        ["gen", "--model", model.to_str().unwrap(), "--prompt", "x", "--steps", "1", "--out", png.to_str().unwrap()];
    let scene = ["scene", "--out", out.to_str().unwrap(), "--count", "1"];
    for (variable, value, takes) in REFUSED {
        for args in [&["devices"][..], &gen, &scene] {
            let run = vkdiff_with(args, &[(variable, value)]);
            let stderr = String::from_utf8_lossy(&run.stderr);
            let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
            assert_eq!(run.status.code(), Some(2), "{variable}={value} {args:?}: {stderr}");
            assert_eq!(errors.len(), 1, "{variable}={value} {args:?}: {stderr}");
            let want = format!("error: {variable}={value}: expected ");
            assert!(errors[0].starts_with(&want) && errors[0].contains(takes), "{args:?}: {}", errors[0]);
        }
    }
    assert!(!png.exists() && !out.exists(), "a refused setting left output");
}

/// `vkdiff devices --json`'s selected device under these variables.
fn selected(env: &[(&str, &str)]) -> serde_json::Value {
    let run = vkdiff_with(&["devices", "--json"], env);
    assert!(run.status.success(), "{env:?}: {}", String::from_utf8_lossy(&run.stderr));
    let list: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    list.as_array().unwrap().iter().find(|d| d["selected"] == true).cloned().expect("a selected device")
}

#[test]
fn a_switch_takes_every_spelling_and_the_plan_says_what_it_chose() {
    for on in ["1", "true", "YES", "on"] {
        let d = selected(&[("VKDIFF_GPU_PATHS", on), ("VKDIFF_QUICK_COMPILE", "0")]);
        let plan = d["kernels"]["plan"].as_str().unwrap();
        assert!(plan.contains("VKDIFF_GPU_PATHS=1: device memory through staging"), "{on}: {plan}");
        assert_eq!(d["kernels"]["subgroup_attention"], false, "{on}: the GPU paths take the GPU's attention");
    }
    let cpu = selected(&[("VKDIFF_GPU_PATHS", "off")]);
    if cpu["kind"] == "cpu" {
        for (value, quick) in [("yes", true), ("false", false)] {
            let d = selected(&[("VKDIFF_QUICK_COMPILE", value)]);
            assert_eq!(d["quick_compile"], quick, "VKDIFF_QUICK_COMPILE={value}");
        }
        assert_eq!(cpu["kernels"]["gemm"], "subgroup", "{cpu}");
    }
}

/// The source files under `dir`, without unit-test modules (they read the settings of the
/// process they run in, as tests do): each file's path and its code before `#[cfg(test)]`.
fn code_under(dir: &std::path::Path) -> Vec<(std::path::PathBuf, String)> {
    let mut files = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap().flatten() {
            let path = entry.path();
            if path.is_dir() {
                stack.push(path);
            } else if path.file_name().is_some_and(|n| n != "tests.rs") {
                let text = std::fs::read_to_string(&path).unwrap();
                files.push((path, text.split("#[cfg(test)]").next().unwrap().to_string()));
            }
        }
    }
    files
}

#[test]
fn the_runtime_reads_no_environment() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("runtime/src");
    let mut readers = Vec::new();
    for (path, code) in code_under(&root) {
        for reader in ["std::env", "env::var", "vars_os", "of_process", "getenv"] {
            if code.contains(reader) {
                readers.push(format!("{}: {reader}", path.display()));
            }
        }
    }
    assert!(readers.is_empty(), "the runtime reads the environment: {readers:?}");
}

/// Every crate's code, the command line's included, is handed the environment `main` read once;
/// `Environment::of_process` itself is the one read.
#[test]
fn only_main_reads_the_process_environment() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut crates = vec![root.join("src")];
    for entry in std::fs::read_dir(root).unwrap().flatten() {
        // The tests' kit reads the environment the tests run in, as tests do.
        let product = entry.file_name() != "testkit" && entry.path().join("Cargo.toml").is_file();
        if product && entry.path().join("src").is_dir() {
            crates.push(entry.path().join("src"));
        }
    }
    let edge = [root.join("src/main.rs"), root.join("setting/src/environment.rs")];
    let mut readers = Vec::new();
    for (path, code) in crates.iter().flat_map(|dir| code_under(dir)) {
        for reader in ["env::var", "vars_os", "var_os", "of_process", "getenv"] {
            if code.contains(reader) && !edge.contains(&path) {
                readers.push(format!("{}: {reader}", path.display()));
            }
        }
    }
    assert!(crates.len() > 10, "the crates are found: {crates:?}");
    assert!(readers.is_empty(), "read the environment below main: {readers:?}");
}
