//! `vkdiff gen` refuses what would lose work or write a false image: an existing output, a
//! depth map of another shape or without valid depth, a model whose output is not a number, and
//! an image written without its latents.

mod cli;

use cli::{error_line_with, scratch, vkdiff};
use std::path::{Path, PathBuf};

fn fixture(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures").join(path)
}

/// The one `error:` line of a failed run.
fn error_line(args: &[&str]) -> String {
    error_line_with(args, &[])
}

fn tiny() -> String {
    fixture("pipeline/tiny-sdxl").display().to_string()
}

fn depth_exr(path: &Path, width: u32, height: u32, depth: impl Fn(u32, u32) -> f32) {
    let values: Vec<f32> =
        (0..height).flat_map(|y| (0..width).map(move |x| (x, y))).map(|(x, y)| depth(x, y)).collect();
    std::fs::write(path, vkdiff_render::exr::encode_single_channel(width, height, "Z", &values)).unwrap();
}

#[test]
fn an_existing_output_is_kept_without_force() {
    let dir = scratch("force");
    let out = dir.join("x.png");
    std::fs::write(&out, b"earlier work").unwrap();
    let line = error_line(&[
        "gen",
        "--model",
        &tiny(),
        "--prompt",
        "x",
        "--steps",
        "1",
        "--width",
        "64",
        "--height",
        "64",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(line.contains("exists; give --force"), "{line}");
    assert_eq!(std::fs::read(&out).unwrap(), b"earlier work");
    let result = vkdiff(&[
        "gen",
        "--model",
        &tiny(),
        "--prompt",
        "x",
        "--steps",
        "1",
        "--width",
        "64",
        "--height",
        "64",
        "--out",
        out.to_str().unwrap(),
        "--force",
    ]);
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    assert!(std::fs::read(&out).unwrap().starts_with(b"\x89PNG"));
}

#[test]
fn depth_of_another_shape_or_without_depth_is_refused() {
    let dir = scratch("depth");
    let out = dir.join("x.png");
    let controlnet = fixture("workflow/controlnet").display().to_string();
    let (wide, empty) = (dir.join("wide.exr"), dir.join("empty.exr"));
    depth_exr(&wide, 128, 64, |x, _| 1.0 + x as f32 / 128.0);
    depth_exr(&empty, 64, 64, |x, _| if x % 2 == 0 { 0.0 } else { f32::INFINITY });
    let base = [
        "gen",
        "--model",
        &tiny(),
        "--controlnet",
        &controlnet,
        "--prompt",
        "x",
        "--steps",
        "1",
        "--out",
        out.to_str().unwrap(),
    ];
    let line =
        error_line(&[&base[..], &["--depth", wide.to_str().unwrap(), "--width", "64", "--height", "64"]].concat());
    assert!(line.contains("128x64") && line.contains("stretched") && line.contains("--width 64 --height 32"), "{line}");
    let line = error_line(&[&base[..], &["--depth", empty.to_str().unwrap()]].concat());
    assert!(line.contains("empty.exr") && line.contains("no pixel holds a valid depth"), "{line}");
    assert!(!out.exists());
    // The same shape at another size is a resize, not a stretch.
    let result =
        vkdiff(&[&base[..], &["--depth", wide.to_str().unwrap(), "--width", "128", "--height", "64"]].concat());
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
}

/// A copy of the tiny model whose `component` tensor `name` is all NaN.
fn model_with_nan(dir: &Path, component: &str, file: &str, name: &str) -> PathBuf {
    let model = dir.join(format!("nan-{component}"));
    std::fs::create_dir_all(model.join(component)).unwrap();
    let source = fixture("pipeline/tiny-sdxl");
    for entry in std::fs::read_dir(&source).unwrap() {
        let entry = entry.unwrap();
        if entry.file_name() != component {
            std::os::unix::fs::symlink(entry.path(), model.join(entry.file_name())).unwrap();
        }
    }
    std::fs::copy(source.join(component).join("config.json"), model.join(component).join("config.json")).unwrap();
    let mut bytes = std::fs::read(source.join(component).join(file)).unwrap();
    let n = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let header: serde_json::Value = serde_json::from_slice(&bytes[8..8 + n]).unwrap();
    let entry = &header[name];
    let [start, end] = [0, 1].map(|i| 8 + n + entry["data_offsets"][i].as_u64().unwrap() as usize);
    let nan: &[u8] = if entry["dtype"] == "F16" { &[0x00, 0x7e] } else { &[0x00, 0x00, 0xc0, 0x7f] };
    for chunk in bytes[start..end].chunks_exact_mut(nan.len()) {
        chunk.copy_from_slice(nan);
    }
    std::fs::write(model.join(component).join(file), bytes).unwrap();
    model
}

#[test]
fn a_network_output_that_is_not_a_number_is_an_error_naming_the_stage() {
    let dir = scratch("nan");
    let out = dir.join("x.png");
    for (component, tensor, stage) in [
        ("unet", "conv_out.bias", "the UNet's output at step 1 of 2"),
        ("vae", "decoder.conv_out.bias", "the VAE decoder's output"),
    ] {
        let model = model_with_nan(&dir, component, "diffusion_pytorch_model.safetensors", tensor);
        let line = error_line(&[
            "gen",
            "--model",
            model.to_str().unwrap(),
            "--prompt",
            "x",
            "--steps",
            "2",
            "--width",
            "64",
            "--height",
            "64",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(line.contains(stage) && line.contains("NaN") && line.contains("--precision f32"), "{line}");
        assert!(!out.exists(), "a {component} NaN wrote an image");
    }
}

#[test]
fn the_image_and_its_latents_are_written_together_or_not_at_all() {
    let dir = scratch("pair");
    let out = dir.join("x.png");
    // A folder where the latents file should go: the image is written, the latents cannot be.
    let latents = dir.join("x.safetensors");
    std::fs::create_dir(&latents).unwrap();
    std::fs::write(latents.join("keep"), b"").unwrap();
    let args =
        ["gen", "--model", &tiny(), "--prompt", "x", "--steps", "1", "--width", "64", "--height", "64", "--force"];
    let line = error_line(
        &[&args[..], &["--out", out.to_str().unwrap(), "--latents-out", latents.to_str().unwrap()]].concat(),
    );
    assert!(line.contains("x.safetensors"), "{line}");
    let left: Vec<String> =
        std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert_eq!(left, vec!["x.safetensors".to_string()], "the image without its latents, or a temporary file, was left");
}

#[test]
fn a_plain_prompt_past_77_tokens_is_cut_with_a_warning() {
    let dir = scratch("long");
    let out = dir.join("x.png");
    let long = "mushrooms on soil ".repeat(30);
    let result = vkdiff(&[
        "gen",
        "--model",
        &tiny(),
        "--prompt",
        &long,
        "--steps",
        "1",
        "--width",
        "64",
        "--height",
        "64",
        "--out",
        out.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(
        result.status.success()
            && stderr.contains("warning: the last 15 tokens")
            && stderr.contains("--prompt-syntax weighted"),
        "{stderr}"
    );
    let result = vkdiff(&[
        "gen",
        "--model",
        &tiny(),
        "--prompt",
        &long,
        "--prompt-syntax",
        "weighted",
        "--steps",
        "1",
        "--width",
        "64",
        "--height",
        "64",
        "--out",
        out.to_str().unwrap(),
        "--force",
    ]);
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(result.status.success() && !stderr.contains("warning"), "{stderr}");
}

#[test]
fn a_cpu_device_is_refused_when_a_gpu_is_required() {
    // CI's only device is lavapipe: `--require-gpu` refuses it before any work, naming the
    // drivers the loader reads, and writes nothing.
    let dir = scratch("require-gpu");
    let out = dir.join("x.png");
    let model = tiny();
    let args = ["gen", "--model", &model, "--prompt", "x", "--steps", "1", "--out", out.to_str().unwrap()];
    let line = error_line(&[&args[..], &["--require-gpu"]].concat());
    assert!(line.contains("a GPU is required") && line.contains("is a CPU") && line.contains("lvp_icd"), "{line}");
    assert!(!out.exists());
    let line = error_line(&[&args[..], &["--device", "0000:99:00.0"]].concat());
    assert!(line.contains("--device names device PCI 0000:99:00.0") && line.contains("vkdiff devices"), "{line}");
}

#[test]
fn a_fragment_shape_the_device_cannot_take_is_refused() {
    // VKDIFF_FRAGMENT names a shape vkdiff builds, which the device must take at a width it is
    // built for: lavapipe pins no 32- or 64-lane subgroups, so 16×16×16 is refused there.
    let dir = scratch("fragment");
    let out = dir.join("x.png");
    let model = tiny();
    let args = ["gen", "--model", &model, "--prompt", "x", "--steps", "1", "--out", out.to_str().unwrap()];
    let run = |fragment: &str| error_line_with(&args, &[("VKDIFF_FRAGMENT", fragment)]);
    let line = run("16x8x16");
    assert!(line.contains("VKDIFF_FRAGMENT=16x8x16: expected one of the shapes vkdiff builds"), "{line}");
    let line = run("16x16x16");
    assert!(line.contains("VKDIFF_FRAGMENT=16x16x16: `") && line.contains("does not take it"), "{line}");
    assert!(!out.exists());
}
