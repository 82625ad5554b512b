//! The CPU references of the benchmarks, run as Python subprocesses in the same benchmark run:
//! the CPU's practical GEMM peak (numpy → OpenBLAS, float32, `tools/cpu_gemm_peak.py`) and the
//! diffusers / torch-fidelity / torch scripts of the other benchmarks.

use std::io::Write;
use std::process::{Command, Stdio};

/// Settings some machines export for older OpenBLAS builds, which force a slower kernel family
/// (e.g. Haswell's AVX2 kernels on an AVX-512 CPU): a reference runs with OpenBLAS's own choice.
const SLOWING_VARIABLES: [&str; 2] = ["OPENBLAS_CORETYPE", "OPENBLAS_L2_SIZE"];

/// `$VKDIFF_REFERENCE_PYTHON` (else python3), ready to run a reference script.
fn reference_python() -> (String, Command) {
    let python = std::env::var("VKDIFF_REFERENCE_PYTHON").unwrap_or_else(|_| "python3".into());
    let mut command = Command::new(&python);
    for name in SLOWING_VARIABLES {
        command.env_remove(name);
    }
    (python, command)
}

const SCRIPT: &str = include_str!("../../tools/cpu_gemm_peak.py");

/// One measured shape.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CpuGemm {
    pub m: usize,
    pub n: usize,
    pub k: usize,
    pub gflops: f64,
    pub library: String,
    /// The kernel family OpenBLAS chose (threadpoolctl's `internal_api` and `architecture`).
    pub kernel: String,
}

/// GFLOP/s for each (M, N, K), or why it could not be measured (no python3 or numpy).
pub fn measure(shapes: &[(usize, usize, usize)]) -> Result<Vec<CpuGemm>, String> {
    let args: Vec<String> = shapes.iter().flat_map(|&(m, n, k)| [m, n, k]).map(|x| x.to_string()).collect();
    run_script(SCRIPT, args, None, None)?
        .lines()
        .map(|line| {
            let v: serde_json::Value = serde_json::from_str(line).map_err(|e| e.to_string())?;
            let get = |k: &str| v[k].as_u64().unwrap_or(0) as usize;
            Ok(CpuGemm {
                m: get("m"),
                n: get("n"),
                k: get("k"),
                gflops: v["gflops"].as_f64().unwrap_or(0.0),
                library: format!(
                    "numpy {} / {}",
                    v["numpy"].as_str().unwrap_or("?"),
                    v["blas"].as_str().unwrap_or("?")
                ),
                kernel: v["kernel"].as_str().unwrap_or("unknown (pip install threadpoolctl to see it)").to_string(),
            })
        })
        .collect()
}

/// Runs `script` with `$VKDIFF_REFERENCE_PYTHON` (else python3), `args` and, if given, `input` on
/// its standard input; its standard output, or why it could not run (the last line of its errors).
/// The Vulkan instances no context holds are destroyed first: a CPU driver may keep the device's
/// memory until then, which a CPU reference needs (`vkdiff_runtime::release_idle_instances`).
fn run_script<S: AsRef<std::ffi::OsStr>>(
    script: &str,
    args: impl IntoIterator<Item = S>,
    input: Option<&str>,
    timeout: Option<std::time::Duration>,
) -> Result<String, String> {
    vkdiff_runtime::release_idle_instances();
    let (python, mut command) = reference_python();
    command.arg("-c").arg(script).args(args).stdin(Stdio::piped()).stdout(Stdio::piped()).stderr(Stdio::piped());
    let mut child = command.spawn().map_err(|e| format!("{python} not runnable ({e})"))?;
    let mut stdin = child.stdin.take().expect("piped");
    if let Some(input) = input {
        stdin.write_all(input.as_bytes()).map_err(|e| format!("{python}: {e}"))?;
    }
    drop(stdin);
    let pid = child.id();
    let (sender, finished) = std::sync::mpsc::channel();
    std::thread::spawn(move || sender.send(child.wait_with_output()));
    let out = match timeout.map_or_else(|| finished.recv().ok(), |t| finished.recv_timeout(t).ok()) {
        Some(out) => out.map_err(|e| format!("{python}: {e}"))?,
        None => {
            let _ = Command::new("kill").args(["-KILL", &pid.to_string()]).status();
            let seconds = timeout.map_or(0, |t| t.as_secs());
            return Err(format!("did not finish in {seconds} s and was stopped"));
        }
    };
    if let Some(signal) = std::os::unix::process::ExitStatusExt::signal(&out.status) {
        let name = if signal == 11 { " (a segmentation fault)" } else { "" };
        return Err(format!("{python} ended by signal {signal}{name}"));
    }
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        return Err(format!("{python}: {}", err.lines().last().unwrap_or("failed")));
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// Runs a reference script (see `run_script`) and reads the JSON line it prints last.
pub fn run_python_reference<S: AsRef<std::ffi::OsStr>>(
    script: &str,
    args: impl IntoIterator<Item = S>,
    input: Option<&str>,
) -> Result<serde_json::Value, String> {
    run_python_reference_within(script, args, input, None)
}

/// [`run_python_reference`], stopped past `timeout` (a reference that may hang on a device).
pub fn run_python_reference_within<S: AsRef<std::ffi::OsStr>>(
    script: &str,
    args: impl IntoIterator<Item = S>,
    input: Option<&str>,
    timeout: Option<std::time::Duration>,
) -> Result<serde_json::Value, String> {
    let out = run_script(script, args, input, timeout)?;
    serde_json::from_str(out.lines().last().unwrap_or("")).map_err(|e| format!("reference output is not JSON: {e}"))
}

/// What ran a diffusers reference, from the fields its script prints.
pub fn label(v: &serde_json::Value) -> String {
    format!(
        "{}, torch {} / diffusers {}",
        v["where"].as_str().unwrap_or("?"),
        v["torch"].as_str().unwrap_or("?"),
        v["diffusers"].as_str().unwrap_or("?"),
    )
}

#[cfg(test)]
mod tests {
    #[test]
    fn references_run_without_the_variables_that_slow_openblas() {
        let (_, command) = super::reference_python();
        let removed: Vec<_> =
            command.get_envs().filter(|(_, value)| value.is_none()).map(|(name, _)| name.to_owned()).collect();
        for name in super::SLOWING_VARIABLES {
            assert!(removed.iter().any(|r| r == name), "{name} reaches the reference process");
        }
    }
}
