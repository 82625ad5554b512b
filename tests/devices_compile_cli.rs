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

/// The GPU CI's drm-shim passes fake (`AMDGPU_GPU_ID` for RADV, `NOUVEAU_CHIPSET` for NVK), and
/// whether it has matrix units (RDNA3's navi31, Ampere's GA104): None on lavapipe.
fn faked_gpu() -> Option<(&'static str, bool)> {
    let var = |k: &str| std::env::var(k).ok().filter(|v| !v.is_empty());
    match (var("AMDGPU_GPU_ID"), var("NOUVEAU_CHIPSET")) {
        (Some(id), _) => Some(("RADV", id == "navi31")),
        (None, Some(chipset)) => Some(("NVK", chipset == "174")),
        _ => None,
    }
}

#[test]
fn every_kernel_a_gpu_runs_compiles_and_sdxl_s_never_spill() {
    let out = census(&[]);
    let compiled = out["compiled"].as_array().unwrap();
    let kernel = |k: &serde_json::Value| k["kernel"].as_str().unwrap().to_string();
    let names: Vec<String> = compiled.iter().map(kernel).collect();
    let mut expected = vec!["gemm_tiled_v4", "conv_tiled_v4", "attention_tiled", "group_norm_stats_v4", "geglu_v4"];
    if let Some((driver, matrix_units)) = faked_gpu() {
        assert!(out["device"].as_str().unwrap().contains(driver), "a {driver} pass on {}", out["device"]);
        if matrix_units {
            expected.extend(["gemm_coop", "conv_coop", "attention_coop"]);
        }
        // A GPU compiler reports its scratch or local memory for every variant: an absent figure
        // (a renamed statistic) must not pass as "no spill".
        if let Some(k) = compiled.iter().find(|k| k["memory_spills"].is_null()) {
            let stats: Vec<&str> = k["statistics"]
                .as_array()
                .into_iter()
                .flatten()
                .flat_map(|e| e.as_object().into_iter().flat_map(|o| o.keys().map(String::as_str)))
                .collect();
            panic!("{} {} reports no spill figure; its statistics: {stats:?}", kernel(k), k["params"]);
        }
    }
    for expected in expected {
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

fn is_load(op: &str) -> bool {
    op.starts_with("buffer_load") || op.starts_with("global_load")
}

fn is_multiply_add(op: &str) -> bool {
    ["v_fma", "v_dual_fmac", "v_dual_fma", "v_pk_fma", "v_wmma"].iter().any(|w| op.starts_with(w))
}

/// The largest loop of one ACO disassembly that loads from device memory (a backward branch's
/// range, labels dropped).
fn aco_loading_loop(disassembly: &str) -> Option<Vec<&str>> {
    let lines: Vec<&str> =
        disassembly.lines().map(|l| l.split(';').next().unwrap().trim()).filter(|l| !l.is_empty()).collect();
    let label_at = |name: &str| lines.iter().position(|l| l.strip_suffix(':') == Some(name));
    let mut loops = Vec::new();
    for (end, line) in lines.iter().enumerate() {
        let target =
            line.strip_prefix("s_cbranch_").or(line.strip_prefix("s_branch")).and_then(|l| l.split_whitespace().last());
        if let Some(start) = target.and_then(label_at).filter(|&start| start < end) {
            loops.push(lines[start..=end].iter().copied().filter(|l| !l.ends_with(':')).collect::<Vec<_>>());
        }
    }
    loops.into_iter().filter(|b| b.iter().any(|op| is_load(op))).max_by_key(|b| b.len())
}

/// Multiply-adds issued between the load at `at` of a loop body and the first `s_waitcnt
/// vmcnt(c)` it must pass going round (loads complete in order: one with `later` loads issued
/// after it is done once c <= later). tools/load_cover.py prints the same for every kernel.
fn load_cover(body: &[&str], at: usize) -> usize {
    let (mut later, mut work) = (0, 0);
    for step in 1..=body.len() {
        let op = body[(at + step) % body.len()];
        let wait =
            op.strip_prefix("s_waitcnt").and_then(|w| w.split("vmcnt(").nth(1)).and_then(|c| c.split(')').next());
        if wait.and_then(|c| c.parse::<usize>().ok()).is_some_and(|c| c <= later) {
            return work;
        }
        later += usize::from(is_load(op));
        work += usize::from(is_multiply_add(op));
    }
    work
}

/// AMD's compiler (RADV's ACO, which prints its code with RADV_DEBUG=shaders) must let the
/// products' K-loops run at least half a step's multiply-adds before each prefetched load is
/// waited for. Masked as they arrived, or fetched under a branch, the loads were waited for
/// before any: the prefetch hid nothing. Other drivers print no ACO code, so this holds on RADV
/// only (CI's drm-shim passes for RDNA3 and RDNA2).
#[test]
fn amd_s_compiler_hides_the_products_loads_behind_their_multiply_adds() {
    let run = command().args(["devices", "--json"]).env("VKDIFF_GPU_PATHS", "1").output().unwrap();
    let devices: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    let device = devices.as_array().unwrap().iter().find(|d| d["selected"] == true).unwrap();
    let radv = device["name"].as_str().unwrap().contains("RADV");
    if let Some((driver, _)) = faked_gpu() {
        assert_eq!(radv, driver == "RADV", "the {driver} pass runs on {}", device["name"]);
    }
    if !radv {
        return;
    }
    let mut kernels = "gemm_tiled_v4,conv_tiled_v4".to_string();
    if !device["cooperative_variant"].is_null() {
        kernels.push_str(",gemm_coop,conv_coop");
    }
    let run = command()
        .args(["devices", "--compile", "--json", "--kernel", &kernels])
        .envs([("VKDIFF_GPU_PATHS", "1"), ("RADV_DEBUG", "shaders"), ("MESA_SHADER_CACHE_DISABLE", "true")])
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let out: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    let shaders: Vec<&str> = stderr.split("\ndisasm:\n").skip(1).map(|s| s.split("\n\n").next().unwrap()).collect();
    let compiled = out["compiled"].as_array().unwrap();
    assert_eq!(shaders.len(), compiled.len(), "one disassembly a variant of {kernels}");
    for (shader, variant) in shaders.iter().zip(compiled) {
        let body = aco_loading_loop(shader).expect("a K-loop that loads");
        let work = body.iter().filter(|op| is_multiply_add(op)).count();
        let least = (0..body.len()).filter(|&i| is_load(body[i])).map(|i| load_cover(&body, i)).min().unwrap();
        let what = format!("{} {}", variant["kernel"], variant["params"]);
        assert!(2 * least >= work, "{what}: a load is waited for after {least} of the step's {work} multiply-adds");
    }
}
