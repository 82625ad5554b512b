//! `vkdiff fid` as a user runs it, held to torch-fidelity (tools/make_fid_fixtures.py): FID and
//! KID between two small folders with the real InceptionV3 architecture (reproducible random
//! weights, given as a safetensors file), the feature cache, and one error line for bad input.

mod cli;

use cli::{scratch, vkdiff};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use vkdiff_formats::write_safetensors_f32;
use vkdiff_networks::RandomInception;

fn fixture(name: &str) -> String {
    format!("{}/tests/fixtures/fid/{name}", env!("CARGO_MANIFEST_DIR"))
}

fn weights(dir: &Path) -> PathBuf {
    let path = dir.join("inception-random.safetensors");
    write_safetensors_f32(&path, &RandomInception::new().tensors(), &Default::default()).unwrap();
    path
}

fn fid_json(args: &[&str]) -> Value {
    fid_json_with(args, &[])
}

fn fid_json_with(args: &[&str], env: &[(&str, &Path)]) -> Value {
    // The network on the GPU paths is tests/unet/inception.rs' part; here the command runs on the
    // default paths, where eleven images take seconds instead of minutes on lavapipe.
    let out = Command::new(env!("CARGO_BIN_EXE_vkdiff"))
        .args([&["fid"], args, &["--json"]].concat())
        .env_remove("VKDIFF_GPU_PATHS")
        .envs(env.iter().copied())
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

fn close(what: &str, got: f64, want: f64, rtol: f64) {
    assert!(
        (got - want).abs() <= rtol * want.abs(),
        "{what}: {got} against torch-fidelity's {want} (relative {:.2e})",
        (got - want).abs() / want.abs()
    );
}

#[test]
fn fid_and_kid_match_torch_fidelity_and_the_cache_reuses_features() {
    let dir = scratch("fid");
    let w = weights(&dir);
    let expected: Value = serde_json::from_str(&std::fs::read_to_string(fixture("expected.json")).unwrap()).unwrap();
    let cache = dir.join("cache");
    let (real, fake) = (fixture("real"), fixture("fake"));
    let args = ["--inception", w.to_str().unwrap(), "--cache-dir", cache.to_str().unwrap(), "--batch", "3"];
    let first = fid_json(&[&[real.as_str(), fake.as_str()], &args[..]].concat());
    assert_eq!(first["kid_subset_size"], expected["kid_subset_size"]);
    close("FID", first["fid"].as_f64().unwrap(), expected["fid"].as_f64().unwrap(), 1e-3);
    close("KID mean", first["kid_mean"].as_f64().unwrap(), expected["kid_mean"].as_f64().unwrap(), 1e-3);
    close("KID std", first["kid_std"].as_f64().unwrap(), expected["kid_std"].as_f64().unwrap(), 1e-3);
    assert_eq!(first["real"]["cached"], 0);

    // Again: every feature comes from the cache, and the figures are the same.
    let second = fid_json(&[&[real.as_str(), fake.as_str()], &args[..]].concat());
    assert_eq!((second["real"]["cached"].as_u64(), second["fake"]["cached"].as_u64()), (Some(5), Some(6)));
    assert_eq!(first["fid"], second["fid"]);
    assert_eq!(first["kid_mean"], second["kid_mean"]);

    // Features another vkdiff version cached (its kernels may differ) are computed again.
    let real_cache = std::fs::read_dir(&cache)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.file_name().unwrap().to_string_lossy().starts_with("real-"))
        .expect("the real folder's cache file");
    let file = vkdiff_formats::SafeTensors::open(&real_cache).unwrap();
    let mut metadata = file.metadata.clone();
    assert_eq!(metadata.get("vkdiff").map(String::as_str), Some(version().as_str()));
    metadata.insert("vkdiff".into(), "0.1.0".into());
    let (shape, values) = file.values("features").unwrap();
    drop(file);
    write_safetensors_f32(&real_cache, &[("features", &shape, &values)], &metadata).unwrap();
    let third = fid_json(&[&[real.as_str(), fake.as_str()], &args[..]].concat());
    assert_eq!((third["real"]["cached"].as_u64(), third["fake"]["cached"].as_u64()), (Some(0), Some(6)));
    assert_eq!(first["fid"], third["fid"]);

    // The weights by Hugging Face id, from a cache laid out as huggingface_hub lays one
    // (refs/main → snapshots/COMMIT/FILE → a relative link into blobs/; tests/hub_cli.rs holds
    // the layout against huggingface_hub itself): the same figures.
    let hub = dir.join("hub");
    let repo = hub.join("models--vkdiff-test--inception");
    let commit = "0123456789abcdef0123456789abcdef01234567";
    std::fs::create_dir_all(repo.join("refs")).unwrap();
    std::fs::create_dir_all(repo.join("blobs")).unwrap();
    std::fs::create_dir_all(repo.join("snapshots").join(commit)).unwrap();
    std::fs::write(repo.join("refs/main"), commit).unwrap();
    std::fs::copy(&w, repo.join("blobs/weights-blob")).unwrap();
    let link = repo.join("snapshots").join(commit).join("inception-random.safetensors");
    std::os::unix::fs::symlink("../../blobs/weights-blob", link).unwrap();
    let by_id = ["--inception", "vkdiff-test/inception/inception-random.safetensors", "--batch", "3"];
    let fourth = fid_json_with(&[&[real.as_str(), fake.as_str()], &by_id[..]].concat(), &[("HF_HUB_CACHE", &hub)]);
    assert_eq!(first["fid"], fourth["fid"]);
}

/// `vkdiff --version`'s version, as the files it writes record it.
fn version() -> String {
    let out = vkdiff(&["--version"]);
    String::from_utf8_lossy(&out.stdout).trim().trim_start_matches("vkdiff ").to_string()
}

#[test]
fn bad_input_is_one_line_before_any_work() {
    let dir = scratch("fid-bad");
    let (real, fake) = (fixture("real"), fixture("fake"));
    let one = dir.join("one");
    std::fs::create_dir_all(&one).unwrap();
    std::fs::copy(fixture("real/real_00.png"), one.join("a.png")).unwrap();
    let garbage = dir.join("garbage.pth");
    std::fs::write(&garbage, b"PK\x03\x04 not really a zip").unwrap();
    let missing = dir.join("missing.pth");
    let cases: [(Vec<&str>, &str); 6] = [
        (vec![&real, &fake, "--inception", garbage.to_str().unwrap(), "--batch", "0"], "--batch"),
        (vec![&real, &fake, "--inception", garbage.to_str().unwrap(), "--kid-subset-size", "1"], "--kid-subset-size"),
        (vec![&real, &fake, "--inception", missing.to_str().unwrap()], "--inception"),
        (vec![&real, one.to_str().unwrap(), "--inception", garbage.to_str().unwrap()], "at least 2"),
        (vec![&real, &fake, "--inception", garbage.to_str().unwrap()], "garbage.pth"),
        (vec![&real, "/nonexistent/folder", "--inception", garbage.to_str().unwrap()], "not a folder"),
    ];
    for (args, needle) in cases {
        let out = vkdiff(&[&["fid"], &args[..]].concat());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} succeeded");
        let last = err.lines().last().unwrap_or("");
        assert!(last.starts_with("error: ") && last.contains(needle), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
    }
}

#[test]
fn every_unreadable_image_of_both_folders_is_named_before_any_encoding() {
    let dir = scratch("fid-unreadable");
    let w = weights(&dir);
    let (real, fake) = (dir.join("real"), dir.join("fake"));
    for (from, to) in [(fixture("real"), &real), (fixture("fake"), &fake)] {
        std::fs::create_dir_all(to).unwrap();
        for entry in std::fs::read_dir(from).unwrap() {
            let path = entry.unwrap().path();
            std::fs::copy(&path, to.join(path.file_name().unwrap())).unwrap();
        }
    }
    // A truncated PNG and a text file named .png among the generated images, an empty .jpg among
    // the photos: the real folder comes first, and is not encoded before they are found.
    let png = std::fs::read(fake.join("fake_02.png")).unwrap();
    std::fs::write(fake.join("fake_02.png"), &png[..png.len() / 2]).unwrap();
    std::fs::write(fake.join("notes.png"), b"not an image\n").unwrap();
    std::fs::write(real.join("empty.jpg"), b"").unwrap();
    let out = vkdiff(&["fid", real.to_str().unwrap(), fake.to_str().unwrap(), "--inception", w.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    let last = err.lines().last().unwrap_or("");
    assert!(last.starts_with("error: 3 of 13 images cannot be read"), "{err}");
    for name in ["fake_02.png", "notes.png", "empty.jpg"] {
        assert!(last.contains(name), "{name} is not named: {err}");
    }
    assert!(!err.lines().any(|l| l.starts_with("real [") || l.starts_with("fake [")), "encoding started: {err}");
}
