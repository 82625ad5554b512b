//! `vkdiff dataset` and its `export`, `merge`, `stats` and `preview`, each given a real failure
//! of every class that applies to it: bad input 2, a missing file 2, the device 3, a full disk
//! 4, an I/O error that is none of these 1.

use super::harness::{case, check, on_full_disk, text, vkdiff};
use super::{fixture, render_set_of, scratch, strs};
use std::path::{Path, PathBuf};

/// A finished render-only set of two scenes in `dir`.
fn finished_set(dir: &Path) -> PathBuf {
    let set = dir.join("set");
    render_set_of(&set, 2, 160, 128, 64);
    set
}

/// A copy of the scene folder `orchard-a` under `dir/scenes`, with `change` made to it.
fn scenes_with(dir: &Path, name: &str, change: &dyn Fn(&Path)) -> PathBuf {
    let scenes = dir.join(name);
    let (from, to) = (fixture("scenes/folders/orchard-a"), scenes.join("orchard-a"));
    std::fs::create_dir_all(&to).unwrap();
    for entry in std::fs::read_dir(&from).unwrap().flatten() {
        std::fs::copy(entry.path(), to.join(entry.file_name())).unwrap();
    }
    change(&to);
    scenes
}

/// A copy of the set `set` as `to/set`, with `change` made to it.
fn copy_of(set: &Path, to: &Path, change: &dyn Fn(&Path)) -> PathBuf {
    std::fs::create_dir_all(to).unwrap();
    let copied = std::process::Command::new("cp").args(["-r", text(set), text(to)]).status().unwrap();
    assert!(copied.success());
    change(&to.join("set"));
    to.join("set")
}

#[test]
fn dataset_exits_by_the_class_of_its_failure() {
    let dir = scratch("codes-dataset");
    let (out, full) = (dir.join("out"), dir.join("full"));
    let model = fixture("pipeline/tiny-sdxl");
    // A set the device refuses is begun (another node resumes it); the refusals write nothing.
    let begun = dir.join("begun");
    // A scene's file that is a folder, and one whose every read fails with EIO (the process's
    // memory at address 0, never mapped).
    let folder_for_file = scenes_with(&dir, "folder-for-file", &|s| {
        std::fs::remove_file(s.join("instances.png")).unwrap();
        std::fs::create_dir(s.join("instances.png")).unwrap();
    });
    let unreadable = scenes_with(&dir, "unreadable", &|s| {
        std::fs::remove_file(s.join("instances.png")).unwrap();
        std::os::unix::fs::symlink("/proc/self/mem", s.join("instances.png")).unwrap();
    });
    let render = |out: &Path, more: &[&str]| {
        let args = ["dataset", "--render-only", "--out", text(out), "--count", "2", "--width", "160"];
        let size = ["--height", "128", "--crops", "2", "--crop-size", "64", "--seed", "11"];
        [&args[..], &size, more].concat().iter().map(|s| s.to_string()).collect::<Vec<_>>()
    };
    let from_scenes =
        |scenes: &Path| vkdiff(&["dataset", "--render-only", "--out", text(&out), "--scenes", text(scenes)]);
    let on_full = render(&full.join("set"), &["--min-free", "0"]);
    check(vec![
        case("a bad value", vkdiff(&strs(&render(&out, &["--crop-min-fraction", "2"]))), 2, &["--crop-min-fraction 2"]),
        case("missing scenes", from_scenes(Path::new("/nonexistent")), 2, &["--scenes /nonexistent", "No such file"]),
        case(
            "a scene's folder for a file",
            from_scenes(&folder_for_file),
            2,
            &["scene orchard-a: instances.png: Is a directory"],
        ),
        case(
            "a scene's I/O error",
            from_scenes(&unreadable),
            1,
            &["scene orchard-a: instances.png: Input/output error"],
        ),
        case(
            "the CPU device refused",
            vkdiff(&["dataset", "--model", text(&model), "--prompt", "a cube", "--out", text(&begun), "--require-gpu"]),
            3,
            &["a GPU is required"],
        ),
        case(
            "a full disk",
            on_full_disk(&full, &[], vkdiff(&strs(&on_full))),
            4,
            &["dataset.json", "No space left on device"],
        ),
    ]);
    assert!(!out.exists());
}

#[test]
fn dataset_export_merge_stats_and_preview_exit_by_the_class_of_their_failure() {
    let dir = scratch("codes-dataset-tools");
    let set = finished_set(&dir);
    let (missing, full) = (dir.join("missing"), dir.join("full"));
    // The set with every image made but not yet merged, and with its manifest cut short.
    let unmerged = copy_of(&set, &dir.join("unmerged"), &|s| std::fs::remove_file(s.join("annotations.json")).unwrap());
    let malformed = copy_of(&set, &dir.join("malformed"), &|s| std::fs::write(s.join("dataset.json"), "{").unwrap());
    let (set_text, missing_text, malformed_text) = (text(&set), text(&missing), text(&malformed));
    let export_to = |set: &str, out: &Path, more: &[&str]| {
        vkdiff(&[&["dataset", "export", set, "--format", "yolo", "--out", text(out)][..], more].concat())
    };
    let export = |set: &str, more: &[&str]| export_to(set, &dir.join("export"), more);
    let tool = |tool: &str, set: &str, more: &[&str]| vkdiff(&[&["dataset", tool, set][..], more].concat());
    let (exported, charts, preview) = (full.join("export"), full.join("charts"), full.join("preview"));
    check(vec![
        case("export: a bad value", export(set_text, &["--val-fraction", "2"]), 2, &["--val-fraction 2 must lie in"]),
        case("export: a missing set", export(missing_text, &[]), 2, &["missing: no dataset.json"]),
        case("export: a malformed set", export(malformed_text, &[]), 2, &["dataset.json", "not JSON"]),
        case(
            "export: a full disk",
            on_full_disk(&full, &[], export_to(set_text, &exported, &[])),
            4,
            &["No space left"],
        ),
        case("merge: a missing set", tool("merge", missing_text, &[]), 2, &["missing: no dataset.json"]),
        case("merge: a malformed set", tool("merge", malformed_text, &[]), 2, &["dataset.json", "not JSON"]),
        case(
            "merge: a full disk",
            on_full_disk(&full, &[&unmerged], tool("merge", text(&full.join("set")), &[])),
            4,
            &["annotations.json", "No space left on device"],
        ),
        case("stats: a missing set", tool("stats", missing_text, &[]), 2, &["missing: no dataset.json"]),
        case("stats: a malformed set", tool("stats", malformed_text, &[]), 2, &["dataset.json", "not JSON"]),
        case(
            "stats: a full disk",
            on_full_disk(&full, &[], tool("stats", set_text, &["--charts", text(&charts)])),
            4,
            &["charts/", "No space left on device"],
        ),
        case("preview: a bad value", tool("preview", set_text, &["--count", "0"]), 2, &["--count must be at least 1"]),
        case("preview: a missing set", tool("preview", missing_text, &[]), 2, &["missing: no dataset.json"]),
        case("preview: a malformed set", tool("preview", malformed_text, &[]), 2, &["dataset.json", "not JSON"]),
        case(
            "preview: a full disk",
            on_full_disk(&full, &[], tool("preview", set_text, &["--out", text(&preview)])),
            4,
            &["preview", "No space left on device"],
        ),
    ]);
}
