//! `vkdiff devices --compile`: every kernel variant the device runs, compiled by its driver. On
//! lavapipe this holds that each compiles; CI also runs these tests on GPUs that Mesa's drm-shim
//! fakes (`.ci/drm-shim`: RADV for AMD's RDNA2 and RDNA3, NVK for NVIDIA's Ampere), whose
//! compilers report spills, and there the kernels a GPU runs SDXL with must not spill.

mod cli;

use cli::{command, error_line_with};

/// The kernels of SDXL's products and attention on a GPU: on the matrix units, and tiled where
/// a GPU has none or the product is f32.
const GPU_HOT_KERNELS: [&str; 7] =
    ["gemm_coop", "conv_coop", "attention_coop", "gemm_tiled", "gemm_tiled_v4", "conv_tiled_v4", "attention_tiled"];

fn census(args: &[&str]) -> serde_json::Value {
    let run =
        command().args(["devices", "--compile", "--json"]).args(args).env("VKDIFF_GPU_PATHS", "1").output().unwrap();
    assert!(run.status.success(), "{args:?}: {}", String::from_utf8_lossy(&run.stderr));
    serde_json::from_slice(&run.stdout).unwrap()
}

#[test]
fn every_kernel_a_gpu_runs_compiles_and_sdxl_s_never_spill() {
    let out = census(&[]);
    let compiled = out["compiled"].as_array().unwrap();
    let kernel = |k: &serde_json::Value| k["kernel"].as_str().unwrap().to_string();
    let names: Vec<String> = compiled.iter().map(kernel).collect();
    for expected in ["gemm_tiled_v4", "conv_tiled_v4", "attention_tiled", "group_norm_stats_v4", "geglu_v4"] {
        assert!(names.iter().any(|n| n == expected), "{expected} is not in the census: {names:?}");
    }
    assert!(!names.iter().any(|n| n.ends_with("_sg")), "the GPU paths take no subgroup-register kernel");
    assert_eq!(out["failed"].as_array().unwrap().len(), 0, "{}", out["failed"]);
    let spilling: Vec<String> = compiled
        .iter()
        .filter(|k| GPU_HOT_KERNELS.contains(&kernel(k).as_str()) && k["memory_spills"].as_u64().is_some_and(|b| b > 0))
        .map(|k| format!("{} {}", kernel(k), k["params"]))
        .collect();
    assert!(spilling.is_empty(), "{} spills registers to memory: {spilling:?}", out["device"]);
}

#[test]
fn a_kernel_list_narrows_the_census_and_an_unknown_name_is_refused() {
    let out = census(&["--kernel", "geglu_v4,layer_norm_v4"]);
    let compiled = out["compiled"].as_array().unwrap();
    let mut names: Vec<&str> = compiled.iter().map(|k| k["kernel"].as_str().unwrap()).collect();
    names.dedup();
    assert_eq!(names, ["layer_norm_v4", "geglu_v4"], "in the library's order");
    assert!(compiled.iter().all(|k| k["seconds"].as_f64().is_some()));
    let line =
        error_line_with(&["devices", "--compile", "--kernel", "gemm_sg,no_such_kernel"], &[("VKDIFF_GPU_PATHS", "1")]);
    assert!(line.contains("--kernel gemm_sg:") && line.contains("runs no kernel of that name"), "{line}");
}

#[test]
fn kernel_names_need_the_census() {
    let run = command().args(["devices", "--kernel", "geglu_v4"]).output().unwrap();
    assert!(!run.status.success());
    assert!(String::from_utf8_lossy(&run.stderr).contains("--compile"));
}
