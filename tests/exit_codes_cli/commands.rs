//! `gen`, `scene`, `eval`, `fid` and `bench report`, each given a real failure of every class
//! that applies to it: bad input 2, a missing file 2, the device 3, a full disk 4, an I/O error
//! that is none of these 1.

use super::harness::{case, check, on_full_disk, text, under_file_size_limit, vkdiff};
use super::{fixture, gen, scratch, strs};
use std::path::{Path, PathBuf};

/// A file whose every read fails with EIO: the process's own memory at address 0, never mapped.
const EIO: &str = "/proc/self/mem";

#[test]
fn gen_exits_by_the_class_of_its_failure() {
    let dir = scratch("codes-gen");
    let (out, full) = (dir.join("x.png"), dir.join("full"));
    let on_full = gen(&full.join("x.png"), &[]);
    check(vec![
        case("a device index that is not there", vkdiff(&strs(&gen(&out, &["--device", "99"]))), 2, &["device 99"]),
        case(
            "a full disk",
            on_full_disk(&full, &[], vkdiff(&strs(&on_full))),
            4,
            &["x.png", "No space left on device"],
        ),
        case(
            "a file-size limit",
            under_file_size_limit(vkdiff(&strs(&gen(&out, &[])))),
            2,
            &["x.png", "File too large"],
        ),
    ]);
    assert!(!out.exists());
}

#[test]
fn scene_exits_by_the_class_of_its_failure() {
    let dir = scratch("codes-scene");
    let (out, full, file) = (dir.join("scene"), dir.join("full"), dir.join("a-file"));
    std::fs::write(&file, "").unwrap();
    std::fs::create_dir_all(dir.join("taken")).unwrap();
    std::fs::write(dir.join("taken/depth.exr"), "").unwrap();
    let under_file = file.join("scene");
    let on_full = full.join("scene");
    check(vec![
        case("a bad value", vkdiff(&["scene", "--out", text(&out), "--width", "10"]), 2, &["--width 10"]),
        case("a scene in the way", vkdiff(&["scene", "--out", text(&dir.join("taken"))]), 2, &["--force"]),
        case(
            "a file where a folder goes",
            vkdiff(&["scene", "--out", text(&under_file)]),
            2,
            &["cannot create folder", "a-file: File exists"],
        ),
        case(
            "a full disk",
            on_full_disk(&full, &[], vkdiff(&["scene", "--out", text(&on_full)])),
            4,
            &["depth.exr", "No space left on device"],
        ),
        case(
            "a file-size limit",
            under_file_size_limit(vkdiff(&["scene", "--out", text(&out)])),
            2,
            &["File too large"],
        ),
    ]);
}

#[test]
fn eval_exits_by_the_class_of_its_failure() {
    let dir = scratch("codes-eval");
    let (gt, pred) = (fixture("eval/gt.json"), fixture("eval/dt_segm.json"));
    let (gt, pred) = (text(&gt), text(&pred));
    let (not_json, stray) = (dir.join("not.json"), dir.join("stray.json"));
    std::fs::write(&not_json, "{").unwrap();
    std::fs::write(&stray, r#"[{"image_id": 99, "category_id": 1, "bbox": [0, 0, 1, 1], "score": 0.5}]"#).unwrap();
    let eval =
        |gt: &str, pred: &str, more: &[&str]| vkdiff(&[&["eval", "--gt", gt, "--pred", pred][..], more].concat());
    check(vec![
        case("a bad value", eval(gt, pred, &["--max-dets", "1,10"]), 2, &["--max-dets takes three numbers"]),
        case(
            "a missing file",
            eval(gt, "/nonexistent.json", &[]),
            2,
            &["cannot read /nonexistent.json", "No such file"],
        ),
        case("a folder as a file", eval(text(&dir), pred, &[]), 2, &["cannot read", "Is a directory"]),
        case("a file that is not JSON", eval(text(&not_json), pred, &[]), 2, &["not.json is not JSON"]),
        case(
            "a malformed result",
            eval(gt, text(&stray), &[]),
            2,
            &["stray.json: results[0]: image 99 is not in the ground truth"],
        ),
        case("an I/O error", eval(EIO, pred, &[]), 1, &["cannot read /proc/self/mem", "Input/output error"]),
    ]);
}

/// torch-fidelity's InceptionV3 architecture with reproducible random weights, in `dir`.
fn inception(dir: &Path) -> PathBuf {
    let path = dir.join("inception-random.safetensors");
    let random = vkdiff_networks::RandomInception::new();
    vkdiff_formats::write_safetensors_f32(&path, &random.tensors(), &Default::default()).unwrap();
    path
}

#[test]
fn fid_exits_by_the_class_of_its_failure() {
    let dir = scratch("codes-fid");
    let weights = inception(&dir);
    let (real, fake) = (fixture("fid/real"), fixture("fid/fake"));
    let garbage = dir.join("garbage.pth");
    std::fs::write(&garbage, b"PK\x03\x04 not really a zip").unwrap();
    let (broken, unreadable) = (dir.join("broken"), dir.join("unreadable"));
    for (folder, second) in [(&broken, None), (&unreadable, Some(EIO))] {
        std::fs::create_dir_all(folder).unwrap();
        std::fs::copy(fake.join("fake_00.png"), folder.join("a.png")).unwrap();
        match second {
            Some(target) => std::os::unix::fs::symlink(target, folder.join("b.png")).unwrap(),
            None => std::fs::write(folder.join("b.png"), "not a png").unwrap(),
        }
    }
    let (full, cache_file) = (dir.join("full"), dir.join("cache-file"));
    std::fs::write(&cache_file, "").unwrap();
    let cache_on_full = full.join("cache");
    // On the default paths: on the GPU paths lavapipe encodes the images in minutes, not seconds.
    let fid = |fake: &Path, weights: &Path, more: &[&str]| {
        let mut command = vkdiff(&[&["fid", text(&real), text(fake), "--inception", text(weights)][..], more].concat());
        command.env_remove("VKDIFF_GPU_PATHS");
        command
    };
    let with = |more: &[&str]| fid(&fake, &weights, more);
    let mut timed_out = with(&[]);
    timed_out.env("VKDIFF_SUBMIT_TIMEOUT", "0.000000001");
    let cache_full = on_full_disk(&full, &[], with(&["--cache-dir", text(&cache_on_full)]));
    check(vec![
        case("a bad value", with(&["--batch", "0"]), 2, &["--batch must be positive"]),
        case(
            "a missing folder",
            fid(Path::new("/nonexistent"), &weights, &[]),
            2,
            &["fake /nonexistent: not a folder"],
        ),
        case("weights that are no weights", fid(&fake, &garbage, &[]), 2, &["garbage.pth"]),
        case("an image that is no image", fid(&broken, &weights, &[]), 2, &["1 of 7 images cannot be read", "b.png"]),
        case(
            "an image with an I/O error",
            fid(&unreadable, &weights, &[]),
            1,
            &["1 of 7 images cannot be read", "Input/output error"],
        ),
        case(
            "a file where the cache goes",
            with(&["--cache-dir", text(&cache_file)]),
            2,
            &["--cache-dir", "cache-file", "File exists"],
        ),
        case("the CPU device refused", with(&["--require-gpu"]), 3, &["a GPU is required"]),
        case("a device that does not finish", timed_out, 3, &["did not finish"]),
        case(
            "a full disk under the cache",
            cache_full,
            4,
            &["cannot write the feature cache", "No space left on device"],
        ),
    ]);
}

#[test]
fn bench_report_exits_by_the_class_of_its_failure() {
    let dir = scratch("codes-bench-report");
    let full = dir.join("full");
    let model = fixture("pipeline/tiny-sdxl");
    let report = |more: &[&str]| -> Vec<String> {
        let base = "bench report --quick --size 64 --only vae --reference-device none --model";
        base.split(' ').chain([text(&model)]).chain(more.iter().copied()).map(String::from).collect()
    };
    let out_on_full = full.join("r.json");
    let missing = dir.join("missing-model");
    check(vec![
        case("a bad value", vkdiff(&["bench", "report", "--size", "100"]), 2, &["--size 100 must be a multiple of 64"]),
        case(
            "a missing model",
            vkdiff(&["bench", "report", "--model", text(&missing)]),
            2,
            &["--model", "missing-model"],
        ),
        case("the CPU device refused", vkdiff(&strs(&report(&["--require-gpu"]))), 3, &["a GPU is required"]),
        case(
            "a full disk",
            on_full_disk(&full, &[], vkdiff(&strs(&report(&["--out", text(&out_on_full)])))),
            4,
            &["r.json", "No space left on device"],
        ),
    ]);
}
