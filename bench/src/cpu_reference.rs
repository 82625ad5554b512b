//! The CPU references of the benchmarks, run as Python subprocesses in the same benchmark run:
//! the CPU's practical GEMM peak (numpy → OpenBLAS, float32, `tools/cpu_gemm_peak.py`) and the
//! diffusers / torch-fidelity / torch scripts of the other benchmarks.

use serde::de::DeserializeOwned;
use serde::Deserialize;
use std::io::Write;
use std::process::{Command, Stdio};
use vkdiff_runtime::Environment;

/// Settings some machines export for older OpenBLAS builds, which force a slower kernel family
/// (e.g. Haswell's AVX2 kernels on an AVX-512 CPU): a reference runs with OpenBLAS's own choice.
const SLOWING_VARIABLES: [&str; 2] = ["OPENBLAS_CORETYPE", "OPENBLAS_L2_SIZE"];

/// `env`'s `$VKDIFF_REFERENCE_PYTHON` (else python3), ready to run a reference script.
fn reference_python(env: &Environment) -> (String, Command) {
    let python = env.get("VKDIFF_REFERENCE_PYTHON").unwrap_or("python3").to_string();
    let mut command = Command::new(&python);
    for name in SLOWING_VARIABLES {
        command.env_remove(name);
    }
    (python, command)
}

/// A reference script carried in the binary, with its path in the repository: every error about
/// what it printed names it.
#[derive(Clone, Copy)]
pub struct Script {
    pub path: &'static str,
    pub text: &'static str,
}

/// The script `tools/FILE`, carried in the binary.
macro_rules! script {
    ($file:literal) => {
        crate::cpu_reference::Script {
            path: concat!("tools/", $file),
            text: include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/../tools/", $file)),
        }
    };
}
pub(crate) use script;

const GEMM_PEAK: Script = script!("cpu_gemm_peak.py");

/// `tools/reference_timing.py`, which the timed references import: carried beside them, and
/// registered as the module before a script that imports it runs.
const TIMING: &str = include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/../tools/reference_timing.py"));
const TIMING_BOOTSTRAP: &str = "import os as _os, sys as _sys, types as _types\n\
    _m = _types.ModuleType('reference_timing')\n\
    exec(_os.environ.pop('VKDIFF_REFERENCE_TIMING'), _m.__dict__)\n\
    _sys.modules['reference_timing'] = _m\n";

/// The program `python -c` runs for `script`: the script, after the timing module's registration
/// where it imports it.
fn program(script: Script, command: &mut Command) -> String {
    if script.text.contains("import reference_timing") {
        command.env("VKDIFF_REFERENCE_TIMING", TIMING);
        format!("{TIMING_BOOTSTRAP}{}", script.text)
    } else {
        script.text.to_string()
    }
}

/// One measured shape, as `tools/cpu_gemm_peak.py` prints it (one JSON object a line).
#[derive(serde::Deserialize)]
struct GemmLine {
    m: usize,
    n: usize,
    k: usize,
    gflops: f64,
    numpy: String,
    blas: String,
    /// Null without threadpoolctl, but always printed.
    #[serde(deserialize_with = "Option::deserialize")]
    kernel: Option<String>,
}

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
pub fn measure(env: &Environment, shapes: &[(usize, usize, usize)]) -> Result<Vec<CpuGemm>, String> {
    let args: Vec<String> = shapes.iter().flat_map(|&(m, n, k)| [m, n, k]).map(|x| x.to_string()).collect();
    run_script(env, GEMM_PEAK, args, None, None)?
        .lines()
        .map(|line| {
            let g: GemmLine = parse(GEMM_PEAK, line)?;
            Ok(CpuGemm {
                m: g.m,
                n: g.n,
                k: g.k,
                gflops: g.gflops,
                library: format!("numpy {} / {}", g.numpy, g.blas),
                kernel: g.kernel.unwrap_or_else(|| "unknown (pip install threadpoolctl to see it)".into()),
            })
        })
        .collect()
}

/// One line a script printed, read as `T`: a field missing or of the wrong type is an error that
/// names it and the script.
fn parse<T: DeserializeOwned>(script: Script, line: &str) -> Result<T, String> {
    serde_json::from_str(line).map_err(|e| format!("{} printed JSON vkdiff cannot read: {e}", script.path))
}

/// Runs `script` with `env`'s `$VKDIFF_REFERENCE_PYTHON` (else python3), `args` and, if given, `input` on
/// its standard input; its standard output, or why it could not run (the script's path, then the
/// last line of its errors). The Vulkan instances no context holds are destroyed first: a CPU
/// driver may keep the device's memory until then, which a CPU reference needs
/// (`vkdiff_runtime::release_idle_instances`); and so is the heap's free memory given back.
fn run_script<S: AsRef<std::ffi::OsStr>>(
    env: &Environment,
    script: Script,
    args: impl IntoIterator<Item = S>,
    input: Option<&str>,
    timeout: Option<std::time::Duration>,
) -> Result<String, String> {
    vkdiff_runtime::release_idle_instances();
    return_free_heap();
    let (python, mut command) = reference_python(env);
    let failed = |why: String| format!("{}: {why}", script.path);
    let program = program(script, &mut command);
    command.arg("-c").arg(program).args(args).stdin(Stdio::piped()).stdout(Stdio::piped()).stderr(Stdio::piped());
    let mut child = command.spawn().map_err(|e| failed(format!("{python} not runnable ({e})")))?;
    let mut stdin = child.stdin.take().expect("piped");
    if let Some(input) = input {
        stdin.write_all(input.as_bytes()).map_err(|e| failed(format!("{python}: {e}")))?;
    }
    drop(stdin);
    let pid = child.id();
    let (sender, finished) = std::sync::mpsc::channel();
    std::thread::spawn(move || sender.send(child.wait_with_output()));
    let out = match timeout.map_or_else(|| finished.recv().ok(), |t| finished.recv_timeout(t).ok()) {
        Some(out) => out.map_err(|e| failed(format!("{python}: {e}")))?,
        None => {
            let _ = Command::new("kill").args(["-KILL", &pid.to_string()]).status();
            let seconds = timeout.map_or(0, |t| t.as_secs());
            return Err(failed(format!("did not finish in {seconds} s and was stopped")));
        }
    };
    if let Some(signal) = std::os::unix::process::ExitStatusExt::signal(&out.status) {
        let name = if signal == 11 { " (a segmentation fault)" } else { "" };
        return Err(failed(format!("{python} ended by signal {signal}{name}")));
    }
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        return Err(failed(format!("{python}: {}", err.lines().last().unwrap_or("failed"))));
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// Gives the heap's free pages back to the system. glibc keeps what a process frees for its own
/// next allocations: after `bench report`'s image under Mesa 22.3 that was 5 GB, beside which
/// diffusers' pipeline for the same image was killed for want of memory on a 24 GiB machine.
fn return_free_heap() {
    // SAFETY: malloc_trim only hands glibc's free pages back; no allocation is touched.
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    unsafe {
        libc::malloc_trim(0);
    }
}

/// Runs a reference script (see `run_script`) and reads the JSON line it prints last as `T`.
pub fn run_python_reference<T: DeserializeOwned, S: AsRef<std::ffi::OsStr>>(
    env: &Environment,
    script: Script,
    args: impl IntoIterator<Item = S>,
    input: Option<&str>,
) -> Result<T, String> {
    run_python_reference_within(env, script, args, input, None)
}

/// [`run_python_reference`], stopped past `timeout` (a reference that may hang on a device).
pub fn run_python_reference_within<T: DeserializeOwned, S: AsRef<std::ffi::OsStr>>(
    env: &Environment,
    script: Script,
    args: impl IntoIterator<Item = S>,
    input: Option<&str>,
    timeout: Option<std::time::Duration>,
) -> Result<T, String> {
    let out = run_script(env, script, args, input, timeout)?;
    parse(script, out.lines().last().unwrap_or(""))
}

/// Where a diffusers reference ran and with what, as its script prints them.
#[derive(Clone, Debug, Deserialize, serde::Serialize)]
pub struct DiffusersRun {
    #[serde(rename = "where")]
    pub place: String,
    pub torch: String,
    pub diffusers: String,
    #[serde(flatten)]
    pub conditions: Conditions,
}

impl DiffusersRun {
    pub fn label(&self) -> String {
        format!("{}, torch {} / diffusers {}; {}", self.place, self.torch, self.diffusers, self.conditions.label())
    }
}

/// How a reference ran (`tools/reference_timing.py`): the switches that make it fastest, the
/// attention backend torch picked (where the script can tell), the host's CPU, load, threads and
/// BLAS, and on CUDA the GPU's clocks before and after.
#[derive(Clone, Debug, Deserialize, serde::Serialize)]
pub struct Conditions {
    pub settings: Vec<String>,
    #[serde(default)]
    pub sdpa: Option<String>,
    pub host: String,
    #[serde(deserialize_with = "Option::deserialize")]
    pub clocks: Option<Vec<String>>,
}

impl Conditions {
    pub fn label(&self) -> String {
        let mut parts = vec![self.settings.join(", ")];
        parts.extend(self.sdpa.as_ref().map(|b| format!("SDPA {b}")));
        parts.push(self.host.clone());
        if let Some(clocks) = &self.clocks {
            parts.push(format!("clocks {}", clocks.join(" → ")));
        }
        parts.retain(|p| !p.is_empty());
        parts.join("; ")
    }
}

/// The same model through torch.compile (CUDA graphs where compiling failed): each sample's
/// wall-clock and, on CUDA, GPU seconds (None where nothing ran), and what ran or why not.
#[derive(Clone, Debug, Deserialize, serde::Serialize)]
pub struct Compiled {
    #[serde(deserialize_with = "Option::deserialize")]
    pub wall: Option<Vec<f64>>,
    #[serde(deserialize_with = "Option::deserialize")]
    pub gpu: Option<Vec<f64>>,
    pub how: String,
}

impl Compiled {
    /// Wall-clock samples in the figure's unit (`scale` per second), or why none ran.
    pub fn samples(&self, scale: f64) -> Result<Vec<f64>, String> {
        match &self.wall {
            Some(wall) => Ok(wall.iter().map(|s| s * scale).collect()),
            None => Err(self.how.clone()),
        }
    }

    /// One line for a bench's row: what ran, and its wall-clock and GPU medians.
    pub fn describe(&self, scale: f64, unit: &str) -> String {
        let median = |v: &Option<Vec<f64>>| v.as_deref().and_then(|v| median(v).map(|m| m * scale));
        match (median(&self.wall), median(&self.gpu)) {
            (Some(w), Some(g)) => format!("{}: {w:.1} {unit} (GPU {g:.1} {unit})", self.how),
            (Some(w), None) => format!("{}: {w:.1} {unit}", self.how),
            _ => self.how.clone(),
        }
    }
}

/// The median of `values`, the report's (`Runs`); None for none or any not finite.
pub fn median(values: &[f64]) -> Option<f64> {
    crate::report::Runs::of(values).map(|runs| runs.median)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, Deserialize)]
    struct Peer {
        load_s: f64,
    }

    #[test]
    fn a_missing_field_names_itself_and_the_script() {
        let sdcpp = Script { path: "tools/sdcpp_reference.py", text: "" };
        let why = parse::<Peer>(sdcpp, r#"{"steps": [1.0]}"#).unwrap_err();
        assert!(why.starts_with("tools/sdcpp_reference.py printed JSON") && why.contains("`load_s`"), "{why}");
        let why = parse::<Peer>(sdcpp, r#"{"load_s": "4"}"#).unwrap_err();
        assert!(why.contains("invalid type: string"), "{why}");
        assert_eq!(parse::<Peer>(sdcpp, r#"{"load_s": 4.5, "more": 1}"#).unwrap().load_s, 4.5);
        let gemm = r#"{"m": 1, "n": 2, "k": 3, "gflops": 9.5, "numpy": "2.3", "blas": "openblas"}"#;
        let why = parse::<GemmLine>(GEMM_PEAK, gemm).err().unwrap();
        assert!(
            why.contains("tools/cpu_gemm_peak.py") && why.contains("`kernel`"),
            "null is allowed, absent is not: {why}"
        );
        let line: GemmLine = parse(GEMM_PEAK, &gemm.replace('}', r#", "kernel": null}"#)).unwrap();
        assert_eq!((line.k, line.kernel), (3, None));
    }

    #[test]
    fn references_run_without_the_variables_that_slow_openblas() {
        let (_, command) = super::reference_python(&Default::default());
        let removed: Vec<_> =
            command.get_envs().filter(|(_, value)| value.is_none()).map(|(name, _)| name.to_owned()).collect();
        for name in super::SLOWING_VARIABLES {
            assert!(removed.iter().any(|r| r == name), "{name} reaches the reference process");
        }
    }
}
