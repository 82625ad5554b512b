//! Models named by Hugging Face ids, found offline where huggingface_hub keeps them
//! (tests/fixtures/hub, laid out by tools/make_hub_cache.py with huggingface_hub's own
//! functions): `$HF_HUB_CACHE`, `$HF_HOME/hub` and `~/.cache/huggingface/hub`, revisions,
//! folders and files inside a repository, and one line (exit code 2) for each way an id fails.

mod cli;

use cli::{command, png_pixels, png_text, scratch};
use std::path::{Path, PathBuf};
use std::process::Output;

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures")
}

/// `vkdiff` with only the cache variables `env` gives (and a HOME with no cache), in `cwd`.
fn run_in(cwd: &Path, args: &[&str], env: &[(&str, &Path)]) -> Output {
    let mut command = command();
    for var in ["HF_HUB_CACHE", "HUGGINGFACE_HUB_CACHE", "HF_HOME", "XDG_CACHE_HOME"] {
        command.env_remove(var);
    }
    command.env("HOME", scratch("hub-empty-home")).env("RUST_BACKTRACE", "0");
    command.args(args).current_dir(cwd).envs(env.iter().map(|(k, v)| (*k, *v))).output().unwrap()
}

fn hub() -> PathBuf {
    fixtures().join("hub")
}

/// One small image of the tiny SDXL: `model` and any further flags.
fn gen_args<'a>(model: &'a str, out: &'a Path, more: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec!["gen", "--model", model, "--prompt", "a red cube", "--steps", "2", "--width", "64"];
    args.extend(["--height", "64", "--seed", "3", "--precision", "f32", "--out", out.to_str().unwrap()]);
    args.extend(more);
    args
}

fn ok(out: &Output) -> String {
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{stderr}");
    stderr
}

fn text(path: &Path, key: &str) -> String {
    png_text(path).into_iter().find(|(k, _)| k == key).map(|(_, v)| v).unwrap_or_default()
}

/// The commit `refs/main` of a fixture repository names.
fn commit(repo: &str) -> String {
    std::fs::read_to_string(hub().join(format!("models--{}/refs/main", repo.replace('/', "--")))).unwrap()
}

#[test]
fn every_model_flag_takes_an_id_from_the_cache_and_records_it() {
    let dir = scratch("hub-every-flag");
    let w = fixtures().join("workflow");
    let (depth, style) = (w.join("control.png"), w.join("style-1.png"));
    let guides = ["--depth", depth.to_str().unwrap(), "--ip-image", style.to_str().unwrap()];
    let by_id = dir.join("id.png");
    let ids = [
        "--controlnet",
        "vkdiff-test/controlnet-depth",
        "--ip-adapter",
        "vkdiff-test/IP-Adapter/sdxl_models/ip-adapter_sdxl.safetensors",
        "--image-encoder",
        "vkdiff-test/IP-Adapter/sdxl_models/image_encoder",
        "--lora",
        "vkdiff-test/lora:0.5",
        "--vae",
        "vkdiff-test/tiny-vae-fp16-fix",
    ];
    let args: Vec<&str> = gen_args("vkdiff-test/tiny-sdxl", &by_id, &ids).into_iter().chain(guides).collect();
    ok(&run_in(&dir, &args, &[("HF_HUB_CACHE", &hub())]));

    let (controlnet, adapter, encoder) =
        (w.join("controlnet"), w.join("ip-adapter_tiny.safetensors"), w.join("image_encoder"));
    let (lora, vae) =
        (format!("{}:0.5", w.join("lora-peft.safetensors").display()), fixtures().join("vae_swap/tiny-vae"));
    let by_path = dir.join("path.png");
    let paths = [
        "--controlnet",
        controlnet.to_str().unwrap(),
        "--ip-adapter",
        adapter.to_str().unwrap(),
        "--image-encoder",
        encoder.to_str().unwrap(),
        "--lora",
        &lora,
        "--vae",
        vae.to_str().unwrap(),
    ];
    let model = fixtures().join("pipeline/tiny-sdxl");
    let args: Vec<&str> = gen_args(model.to_str().unwrap(), &by_path, &paths).into_iter().chain(guides).collect();
    ok(&run_in(&dir, &args, &[]));
    assert_eq!(png_pixels(&by_id), png_pixels(&by_path), "the same files by id and by path");

    // Recorded as ORG/NAME@COMMIT[/PATH]: the same on every machine, whatever its cache folder.
    let sdxl = commit("vkdiff-test/tiny-sdxl");
    assert_eq!(text(&by_id, "model"), format!("vkdiff-test/tiny-sdxl@{sdxl}"));
    assert_eq!(
        text(&by_id, "controlnet"),
        format!("vkdiff-test/controlnet-depth@{}", commit("vkdiff-test/controlnet-depth"))
    );
    let ip = commit("vkdiff-test/IP-Adapter");
    assert_eq!(
        text(&by_id, "ip_adapter"),
        format!("vkdiff-test/IP-Adapter@{ip}/sdxl_models/ip-adapter_sdxl.safetensors")
    );
    assert_eq!(text(&by_id, "image_encoder"), format!("vkdiff-test/IP-Adapter@{ip}/sdxl_models/image_encoder"));
    let lora = commit("vkdiff-test/lora");
    assert_eq!(text(&by_id, "loras"), format!("vkdiff-test/lora@{lora}/pytorch_lora_weights.safetensors:0.5"));
    assert_eq!(
        text(&by_id, "vae"),
        format!("vkdiff-test/tiny-vae-fp16-fix@{}", commit("vkdiff-test/tiny-vae-fp16-fix"))
    );
    assert_eq!(text(&by_path, "vae"), vae.display().to_string());
    // The recorded id is itself a name every flag takes.
    let again = dir.join("again.png");
    ok(&run_in(&dir, &gen_args(&text(&by_id, "model"), &again, &[]), &[("HF_HUB_CACHE", &hub())]));
}

#[test]
fn the_cache_is_found_where_huggingface_hub_keeps_it() {
    let dir = scratch("hub-where");
    let local = dir.join("local.png");
    let model = fixtures().join("pipeline/tiny-sdxl");
    ok(&run_in(&dir, &gen_args(model.to_str().unwrap(), &local, &[]), &[]));
    let hf_home = dir.join("hf-home");
    std::fs::create_dir_all(&hf_home).unwrap();
    std::os::unix::fs::symlink(hub(), hf_home.join("hub")).unwrap();
    let home = dir.join("home");
    std::fs::create_dir_all(home.join(".cache/huggingface")).unwrap();
    std::os::unix::fs::symlink(hub(), home.join(".cache/huggingface/hub")).unwrap();
    let xdg = dir.join("xdg");
    std::fs::create_dir_all(xdg.join("huggingface")).unwrap();
    std::os::unix::fs::symlink(hub(), xdg.join("huggingface/hub")).unwrap();
    let places: [(&str, &[(&str, &Path)]); 4] = [
        ("HF_HUB_CACHE", &[("HF_HUB_CACHE", &hub())]),
        ("HF_HOME", &[("HF_HOME", &hf_home)]),
        ("XDG_CACHE_HOME", &[("XDG_CACHE_HOME", &xdg)]),
        ("~/.cache/huggingface/hub", &[("HOME", &home)]),
    ];
    for (i, (place, env)) in places.iter().enumerate() {
        let out = dir.join(format!("{i}.png"));
        // v1 is a second ref to the same commit.
        let id = if i % 2 == 0 { "vkdiff-test/tiny-sdxl" } else { "vkdiff-test/tiny-sdxl@v1" };
        ok(&run_in(&dir, &gen_args(id, &out, &[]), env));
        assert_eq!(png_pixels(&out), png_pixels(&local), "{place}");
    }
}

/// The one `error:` line of a refused run, which must exit 2 and write nothing.
fn refusal(cwd: &Path, args: &[&str], env: &[(&str, &Path)]) -> String {
    let out = run_in(cwd, args, env);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert_eq!(errors.len(), 1, "{stderr}");
    errors[0].to_string()
}

#[test]
fn a_model_not_in_the_cache_is_one_line_with_its_download() {
    let dir = scratch("hub-refusals");
    let out = dir.join("never.png");
    let env: &[(&str, &Path)] = &[("HF_HUB_CACHE", &hub())];
    let line = refusal(&dir, &gen_args("vkdiff-test/not-downloaded", &out, &[]), env);
    assert!(
        line.contains("not in the Hugging Face cache") && line.contains("hf download vkdiff-test/not-downloaded"),
        "{line}"
    );
    let line = refusal(&dir, &gen_args("vkdiff-test/tiny-sdxl@v9", &out, &[]), env);
    assert!(line.contains("no revision `v9`") && line.contains("main, v1") && line.contains("--revision v9"), "{line}");
    let file = "vkdiff-test/IP-Adapter/sdxl_models/ip-adapter-plus_sdxl.safetensors";
    let enc = "vkdiff-test/IP-Adapter/sdxl_models/image_encoder";
    let line =
        refusal(&dir, &gen_args("vkdiff-test/tiny-sdxl", &out, &["--ip-adapter", file, "--image-encoder", enc]), env);
    assert!(
        line.starts_with(&format!("error: --ip-adapter {file}:"))
            && line.contains("hf download vkdiff-test/IP-Adapter sdxl_models/ip-adapter-plus_sdxl.safetensors"),
        "{line}"
    );

    // An interrupted download: the snapshot's link points to a blob that never arrived.
    let cache = dir.join("broken");
    let repo = cache.join("models--vkdiff-test--tiny-sdxl");
    let snapshot = repo.join("snapshots/0123456789abcdef0123456789abcdef01234567");
    std::fs::create_dir_all(snapshot.join("unet")).unwrap();
    std::fs::create_dir_all(repo.join("refs")).unwrap();
    std::fs::write(repo.join("refs/main"), "0123456789abcdef0123456789abcdef01234567").unwrap();
    std::os::unix::fs::symlink("../../../blobs/feed", snapshot.join("unet/diffusion_pytorch_model.safetensors"))
        .unwrap();
    let line = refusal(&dir, &gen_args("vkdiff-test/tiny-sdxl", &out, &[]), &[("HF_HUB_CACHE", &cache)]);
    assert!(
        line.contains("unet/diffusion_pytorch_model.safetensors in the Hugging Face cache is a link to a missing blob")
            && line.contains("hf download vkdiff-test/tiny-sdxl unet/diffusion_pytorch_model.safetensors"),
        "{line}"
    );
    assert!(!out.exists());
}

#[test]
fn a_local_folder_named_like_an_id_wins_and_says_so() {
    let dir = scratch("hub-local-wins");
    std::fs::create_dir_all(dir.join("vkdiff-test")).unwrap();
    std::os::unix::fs::symlink(fixtures().join("pipeline/tiny-sdxl"), dir.join("vkdiff-test/tiny-sdxl")).unwrap();
    let out = dir.join("local.png");
    let stderr = ok(&run_in(&dir, &gen_args("vkdiff-test/tiny-sdxl", &out, &[]), &[("HF_HUB_CACHE", &hub())]));
    let notes: Vec<&str> = stderr.lines().filter(|l| l.starts_with("note: --model vkdiff-test/tiny-sdxl")).collect();
    assert_eq!(notes.len(), 1, "{stderr}");
    assert!(notes[0].contains("local path") && notes[0].contains("not used"), "{}", notes[0]);
    assert_eq!(text(&out, "model"), "vkdiff-test/tiny-sdxl");
}

#[test]
fn a_dataset_records_its_models_by_id_and_resumes_on_another_cache_folder() {
    let dir = scratch("hub-dataset");
    let set = dir.join("set");
    let args = [
        "dataset",
        "--out",
        set.to_str().unwrap(),
        "--count",
        "1",
        "--width",
        "96",
        "--height",
        "64",
        "--steps",
        "1",
        "--prompt",
        "white button mushrooms",
        "-m",
        "vkdiff-test/tiny-sdxl",
        "--vae",
        "vkdiff-test/tiny-vae-fp16-fix",
    ];
    ok(&run_in(&dir, &args, &[("HF_HUB_CACHE", &hub())]));
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(set.join("dataset.json")).unwrap()).unwrap();
    let settings = &manifest["settings"];
    let recorded = |key: &str| settings[key].as_str().map(String::from).unwrap_or_else(|| settings.to_string());
    assert_eq!(recorded("model"), format!("vkdiff-test/tiny-sdxl@{}", commit("vkdiff-test/tiny-sdxl")));
    assert_eq!(recorded("vae"), format!("vkdiff-test/tiny-vae-fp16-fix@{}", commit("vkdiff-test/tiny-vae-fp16-fix")));
    // Another machine keeps its cache elsewhere: the same ids are the same settings.
    let elsewhere = dir.join("elsewhere");
    std::fs::create_dir_all(&elsewhere).unwrap();
    std::os::unix::fs::symlink(hub(), elsewhere.join("hub")).unwrap();
    let again = ok(&run_in(&dir, &args, &[("HF_HOME", &elsewhere)]));
    assert!(again.contains("0 to make, 1 already done"), "{again}");
}
