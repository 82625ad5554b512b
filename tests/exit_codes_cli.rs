//! How a run ends, as a scheduler reads it: exit code 2 for usage and bad input, 3 for the
//! device, 4 for a stop the same command resumes (a signal, a full disk: dataset_disk_cli.rs),
//! 1 for anything else, each from a real failure of its kind; every command and `dataset`
//! subcommand given each class of failure that applies to it, as tables (exit_codes_cli/); and
//! a set begun by another vkdiff version, refused in one line with nothing changed unless
//! `--allow-version-change`.

mod cli;
#[path = "exit_codes_cli/commands.rs"]
mod commands;
#[path = "exit_codes_cli/dataset.rs"]
mod dataset;
#[path = "exit_codes_cli/harness.rs"]
mod harness;

use cli::{command, render_set_of, scratch, tree};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures").join(name)
}

fn run(args: &[&str], env: &[(&str, &str)]) -> Output {
    command().args(args).env("RUST_BACKTRACE", "0").envs(env.iter().copied()).output().unwrap()
}

/// The exit code and the one `error:` line of a failed run.
fn failure(args: &[&str], env: &[(&str, &str)]) -> (i32, String) {
    failure_of(command().args(args).env("RUST_BACKTRACE", "0").envs(env.iter().copied()))
}

/// The exit code and the one `error:` line of a failed run of `command`.
fn failure_of(command: &mut Command) -> (i32, String) {
    let out = command.output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
    assert!(errors.len() == 1, "{command:?}: {stderr}");
    let code = out
        .status
        .code()
        .unwrap_or_else(|| panic!("{command:?} ended by {:?}, not an exit code: {stderr}", out.status));
    (code, errors[0].to_string())
}

/// A one-step tiny image into `out`, and `more` flags.
fn gen<'a>(out: &'a Path, more: &[&'a str]) -> Vec<String> {
    let model = fixture("pipeline/tiny-sdxl");
    let mut args: Vec<String> =
        ["gen", "--model", model.to_str().unwrap(), "--prompt", "a cube", "--steps", "1", "--width", "64"]
            .map(String::from)
            .to_vec();
    args.extend(["--height", "64", "--precision", "f32", "--out", out.to_str().unwrap()].map(String::from));
    args.extend(more.iter().map(|s| s.to_string()));
    args
}

fn strs(args: &[String]) -> Vec<&str> {
    args.iter().map(String::as_str).collect()
}

#[test]
fn usage_and_bad_input_exit_2() {
    let dir = scratch("exit-2");
    let out = dir.join("x.png");
    let (code, _) = (run(&["gen", "--no-such-flag"], &[]).status.code(), ());
    assert_eq!(code, Some(2), "clap's usage error");
    let missing = dir.join("missing-model");
    let mut args = gen(&out, &[]);
    args[2] = missing.display().to_string();
    let (code, line) = failure(&strs(&args), &[]);
    assert_eq!(code, 2, "{line}");
    // A file that is not what its flag takes: a LoRA given as the VAE.
    let lora = fixture("workflow/lora-peft.safetensors");
    let (code, line) = failure(&strs(&gen(&out, &["--vae", lora.to_str().unwrap()])), &[]);
    assert!(code == 2 && line.contains("--vae") && line.contains("not a single file with a VAE"), "{code}: {line}");
    let set = dir.join("set");
    let set_args =
        ["dataset", "--render-only", "--out", set.to_str().unwrap(), "--crops", "2", "--crop-min-fraction", "2"];
    let (code, line) = failure(&set_args, &[]);
    assert!(code == 2 && line.contains("--crop-min-fraction 2"), "{code}: {line}");
    assert!(!set.exists());
    assert!(!out.exists());
}

/// The tiny pipeline with one UNet weight stored as ComfyUI's scaled fp8 writes it: the weight in
/// F8_E4M3 (zeros) and an f32 `….scale_weight` beside it; every other part linked from the fixture.
fn scaled_fp8_pipeline(dir: &Path) -> PathBuf {
    let source = fixture("pipeline/tiny-sdxl");
    let model = dir.join("tiny-sdxl-scaled-fp8");
    std::fs::create_dir_all(model.join("unet")).unwrap();
    for part in std::fs::read_dir(&source).unwrap().map(|e| e.unwrap().file_name()) {
        if part != "unet" {
            std::os::unix::fs::symlink(source.join(&part), model.join(&part)).unwrap();
        }
    }
    std::fs::copy(source.join("unet/config.json"), model.join("unet/config.json")).unwrap();
    let weights = std::fs::read(source.join("unet/diffusion_pytorch_model.safetensors")).unwrap();
    let n = u64::from_le_bytes(weights[..8].try_into().unwrap()) as usize;
    let header: serde_json::Map<String, serde_json::Value> = serde_json::from_slice(&weights[8..8 + n]).unwrap();
    let data = &weights[8 + n..];
    let (weight, scale) = ("conv_in.weight", "conv_in.scale_weight");
    let mut tensors: Vec<(String, String, Vec<u64>, Vec<u8>)> = Vec::new();
    for (name, entry) in header.iter().filter(|(name, _)| *name != "__metadata__") {
        let shape: Vec<u64> = entry["shape"].as_array().unwrap().iter().map(|d| d.as_u64().unwrap()).collect();
        let [start, end] = [0, 1].map(|i| entry["data_offsets"][i].as_u64().unwrap() as usize);
        let (dtype, bytes) = match name == weight {
            true => ("F8_E4M3".to_string(), vec![0u8; shape.iter().product::<u64>() as usize]),
            false => (entry["dtype"].as_str().unwrap().to_string(), data[start..end].to_vec()),
        };
        tensors.push((name.clone(), dtype, shape, bytes));
    }
    tensors.push((scale.into(), "F32".into(), vec![], 1f32.to_le_bytes().to_vec()));
    let (mut out_header, mut out_data) = (serde_json::Map::new(), Vec::new());
    for (name, dtype, shape, bytes) in tensors {
        let at = out_data.len();
        out_data.extend(bytes);
        let offsets = [at, out_data.len()];
        out_header.insert(name, serde_json::json!({"dtype": dtype, "shape": shape, "data_offsets": offsets}));
    }
    let header = serde_json::to_vec(&out_header).unwrap();
    let mut file = (header.len() as u64).to_le_bytes().to_vec();
    file.extend(header);
    file.extend(out_data);
    std::fs::write(model.join("unet/diffusion_pytorch_model.safetensors"), file).unwrap();
    model
}

#[test]
fn a_scaled_fp8_weight_exits_2_naming_it_and_writes_nothing() {
    let dir = scratch("exit-2-scaled-fp8");
    let out = dir.join("x.png");
    let mut args = gen(&out, &[]);
    args[2] = scaled_fp8_pipeline(&dir).display().to_string();
    let (code, line) = failure(&strs(&args), &[]);
    let named = "tensor `conv_in.weight`";
    assert!(
        code == 2 && line.contains(named) && line.contains("fp8 scaled by `conv_in.scale_weight`"),
        "{code}: {line}"
    );
    assert!(!out.exists());
}

#[test]
fn device_failures_exit_3() {
    let dir = scratch("exit-3");
    let out = dir.join("x.png");
    // No Vulkan driver at all.
    let (code, line) = failure(&strs(&gen(&out, &[])), &[("VK_DRIVER_FILES", "/nonexistent/icd.json")]);
    assert!(
        code == 3 && line.contains("no Vulkan driver found (VK_DRIVER_FILES=/nonexistent/icd.json)"),
        "{code}: {line}"
    );
    // CI's only device is lavapipe, which --require-gpu refuses.
    let (code, line) = failure(&strs(&gen(&out, &["--require-gpu"])), &[]);
    assert!(code == 3 && line.contains("a GPU is required"), "{code}: {line}");
    // A device that does not finish a submission in time.
    let (code, line) = failure(&strs(&gen(&out, &[])), &[("VKDIFF_SUBMIT_TIMEOUT", "0.000000001")]);
    assert!(code == 3 && line.contains("did not finish"), "{code}: {line}");
    assert!(!out.exists());
}

#[test]
fn a_non_finite_image_exits_1() {
    // A VAE with a NaN in its output layer (as a diverged fine-tune leaves): the run stops at the
    // decode, naming it, and writes nothing.
    let dir = scratch("exit-1");
    let vae = dir.join("vae");
    std::fs::create_dir_all(&vae).unwrap();
    let source = fixture("vae_swap/tiny-vae");
    std::fs::copy(source.join("config.json"), vae.join("config.json")).unwrap();
    let file = vkdiff_formats::SafeTensors::open(&source.join("diffusion_pytorch_model.safetensors")).unwrap();
    let mut tensors: Vec<(String, Vec<usize>, Vec<f32>)> = Vec::new();
    for name in file.entries.keys() {
        let (shape, mut values) = file.values(name).unwrap();
        if name == "decoder.conv_out.bias" {
            values[0] = f32::NAN;
        }
        tensors.push((name.clone(), shape, values));
    }
    let refs: Vec<(&str, &[usize], &[f32])> = tensors.iter().map(|(n, s, v)| (n.as_str(), &s[..], &v[..])).collect();
    vkdiff_formats::write_safetensors_f32(&vae.join("diffusion_pytorch_model.safetensors"), &refs, &BTreeMap::new())
        .unwrap();
    let out = dir.join("x.png");
    let (code, line) = failure(&strs(&gen(&out, &["--vae", vae.to_str().unwrap()])), &[]);
    assert!(code == 1 && line.contains("NaN or infinite"), "{code}: {line}");
    assert!(!out.exists());
}

fn render_args(dir: &Path, count: &str) -> Vec<String> {
    let args = ["dataset", "--render-only", "--out", dir.to_str().unwrap(), "--count", count, "--seed", "5"];
    let size = ["--width", "320", "--height", "256", "--crops", "2", "--crop-size", "128", "--threads", "1"];
    args.iter().chain(&size).map(|s| s.to_string()).collect()
}

#[test]
fn a_signal_stops_a_set_cleanly_with_exit_4_and_the_same_command_resumes() {
    let root = scratch("exit-4");
    let (dir, reference) = (root.join("set"), root.join("reference"));
    let args = render_args(&dir, "150");
    let mut child = command().args(&args).stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap();
    let records = || std::fs::read_dir(dir.join("records")).map_or(0, |d| d.count());
    while records() < 4 && child.try_wait().unwrap().is_none() {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    let kill = std::process::Command::new("kill").args(["-TERM", &child.id().to_string()]).status().unwrap();
    assert!(kill.success());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(4), "{stderr}");
    assert!(stderr.contains("error: stopped by a signal with") && stderr.contains("run the same command"), "{stderr}");
    let done = records();
    assert!((4..300).contains(&done), "stopped part-way: {done} of 300 images");
    assert!(!dir.join("annotations.json").exists());
    let resumed = command().args(&args).output().unwrap();
    assert!(resumed.status.success(), "{}", String::from_utf8_lossy(&resumed.stderr));
    let straight = command().args(render_args(&reference, "150")).output().unwrap();
    assert!(straight.status.success());
    assert!(tree(&dir) == tree(&reference), "the resumed set differs from an unhindered run's");
}

/// Sets the version that made the set in `dir`'s dataset.json.
fn made_by(dir: &Path, version: &str) {
    let path = dir.join("dataset.json");
    let mut manifest: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    manifest["vkdiff"] = version.into();
    std::fs::write(&path, serde_json::to_string_pretty(&manifest).unwrap()).unwrap();
}

#[test]
fn a_set_begun_by_another_version_is_refused_unless_allowed() {
    let root = scratch("versions");
    let dir = root.join("set");
    render_set_of(&dir, 2, 160, 128, 64);
    std::fs::remove_file(dir.join("annotations.json")).unwrap();
    std::fs::remove_file(dir.join("records/000003.json")).unwrap();
    made_by(&dir, "0.1.0");
    let this =
        String::from_utf8_lossy(&run(&["--version"], &[]).stdout).trim().trim_start_matches("vkdiff ").to_string();
    let before = tree(&dir);
    let args = ["dataset", "--render-only", "--out", dir.to_str().unwrap(), "--seed", "11", "--crops", "2"];
    let size = ["--count", "2", "--width", "160", "--height", "128", "--crop-size", "64"];
    let resume: Vec<&str> = args.iter().chain(&size).copied().collect();
    let (code, line) = failure(&resume, &[]);
    assert_eq!(code, 2, "{line}");
    assert!(line.contains("made by vkdiff 0.1.0") && line.contains(&format!("this is vkdiff {this}")), "{line}");
    assert!(line.contains("--allow-version-change"), "{line}");
    let (code, line) = failure(&["dataset", "merge", dir.to_str().unwrap()], &[]);
    assert!(code == 2 && line.contains("made by vkdiff 0.1.0"), "{line}");
    assert!(tree(&dir) == before, "a refused run changed the folder");

    let allowed: Vec<&str> = resume.iter().copied().chain(["--allow-version-change"]).collect();
    let out = run(&allowed, &[]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("dataset.json")).unwrap()).unwrap();
    assert_eq!(manifest["vkdiff"], "0.1.0", "the set keeps the version that made it");
    assert_eq!(manifest["versions_allowed"], serde_json::json!([this]));
    assert!(dir.join("annotations.json").is_file(), "the one missing image made, the set merged");
    // Once allowed, this version needs no flag.
    let out = run(&resume, &[]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

/// The few-step settings a sampler cannot run, and a swapped UNet that is none: one line naming
/// what is wrong, exit code 2, before any model loads.
#[test]
fn few_step_settings_a_sampler_lacks_exit_2_before_loading() {
    let dir = scratch("few-step-refusals");
    let out = dir.join("x.png");
    let lora = fixture("workflow/lora-peft.safetensors");
    let missing = dir.join("missing_unet.safetensors");
    let cases: [(&[&str], &str); 8] = [
        (&["--sampler", "lcm", "--timestep-spacing", "trailing"], "lcm has no timestep spacing"),
        (&["--sampler", "euler_a", "--timesteps", "999,499"], "euler_a takes no custom timesteps"),
        (&["--timesteps", "499,999"], "must be strictly descending"),
        (&["--eta", "0.5"], "eta 0.5 is TCD's gamma; euler takes none"),
        (&["--sampler", "tcd", "--eta", "2"], "must lie in [0, 1]"),
        (&["--sampler", "euler_a", "--prediction-type", "sample"], "prediction_type \"sample\""),
        (&["--unet", lora.to_str().unwrap()], "--unet"),
        (&["--unet", missing.to_str().unwrap()], "--unet"),
    ];
    for (more, want) in cases {
        let mut args = gen(&out, more);
        if more.contains(&"--timesteps") {
            // The given timesteps count the steps.
            let at = args.iter().position(|a| a == "--steps").unwrap();
            args.drain(at..at + 2);
        }
        let (code, line) = failure(&strs(&args), &[]);
        assert!(code == 2 && line.contains(want), "{more:?}: {code}: {line}");
        let stderr = String::from_utf8_lossy(&run(&strs(&args), &[]).stderr).into_owned();
        assert!(!stderr.contains("loading"), "{more:?} loaded a model before refusing: {stderr}");
    }
    // LCM's timesteps come from its 50-step distillation schedule; --steps counts the given ones.
    let args = gen(&out, &["--sampler", "lcm"]);
    let mut args = strs(&args);
    let steps = args.iter().position(|a| *a == "--steps").unwrap();
    args[steps + 1] = "60";
    let (code, line) = failure(&args, &[]);
    assert!(code == 2 && line.contains("60 steps exceed original_inference_steps 50"), "{code}: {line}");
    args.extend(["--timesteps", "999,499"]);
    let (code, line) = failure(&args, &[]);
    assert!(code == 2 && line.contains("--timesteps"), "{code}: {line}");
    assert!(!out.exists());
}
