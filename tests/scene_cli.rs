//! `vkdiff scene` and `vkdiff bench scene` as a user runs them.

mod cli;

use cli::{scratch, vkdiff};

const SMALL: [&str; 4] = ["--width", "320", "--height", "180"];

#[test]
fn scene_writes_the_folder_with_its_crops() {
    let out = scratch("scene").join("bed");
    let out_arg = out.to_str().unwrap();
    let result = vkdiff(
        &[
            &["scene", "--seed", "3", "--out", out_arg, "--crops", "2", "--crop-size", "128", "--threads", "1"][..],
            &SMALL,
        ]
        .concat(),
    );
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    assert_eq!(String::from_utf8_lossy(&result.stdout).trim(), format!("wrote scene 3 to {out_arg}"));
    for file in [
        "depth.exr",
        "instances.png",
        "categories.json",
        "annotations.json",
        "camera.json",
        "control.png",
        "preview.png",
        "shaded.png",
        "crops/1/categories.json",
        "crops/1/depth.exr",
        "crops/1/shaded.png",
        "crops/1/camera.json",
    ] {
        assert!(out.join(file).is_file(), "{file}");
    }
}

#[test]
fn bad_arguments_print_one_error_line_and_write_nothing() {
    let root = scratch("bad");
    let out = root.join("bed");
    let out_arg = out.to_str().unwrap();
    for (args, message) in [
        (vec!["--crops", "2", "--crop-size", "400"], "--crop-size 400: must lie in [1, 180] to fit the 320×180 frame"),
        (vec!["--density", "-1"], "--density -1: must be a number ≥ 0 (mushrooms per m²)"),
        (vec!["--clumping", "2"], "--clumping 2: must lie in [0, 1]"),
    ] {
        let result = vkdiff(&[&["scene", "--out", out_arg][..], &SMALL, &args].concat());
        assert_eq!(result.status.code(), Some(2), "{args:?}: bad input exits 2");
        // One line: the binary's error prefix, then the message.
        let stderr = String::from_utf8_lossy(&result.stderr);
        assert!(stderr.trim().lines().count() == 1 && stderr.trim().ends_with(message), "{args:?}: {stderr}");
        assert_eq!(std::fs::read_dir(&root).unwrap().count(), 0, "{args:?} left files behind");
    }
}

#[test]
fn bench_scene_reports_frames_per_second_against_the_paper() {
    let result = vkdiff(&[&["bench", "scene", "--frames", "2"][..], &SMALL].concat());
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    let report = String::from_utf8_lossy(&result.stdout);
    for needle in ["raster", "coco", "frames/s", "the paper's 12 s/frame", "visible instances per frame"] {
        assert!(report.contains(needle), "{needle} missing from:\n{report}");
    }
}
