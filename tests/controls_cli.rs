//! `vkdiff dataset --controls`: the controls a scene's labels give, written beside the depth
//! control, held to tools/make_control_fixtures.py's numpy computation through the whole command
//! (scene folders read, frames made into images, PNGs written and recorded), listed in the COCO
//! entries and dataset.json, shown as layers of the preview page (looked at in Chromium), and
//! nothing of it in a set made without them; scenes that carry the renderer's normals give
//! the numpy normals made from those.

mod cli;

use cli::{chromium, png_pixels, scratch, screenshot, vkdiff};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Output;

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures")
}

fn read_json(path: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

/// A render-only set of the first two scene folders (160×128 whole frames) with `extra` flags.
fn dataset_of_two(out: &Path, extra: &[&str]) -> Output {
    let scenes = fixtures().join("scenes/folders");
    let args = ["dataset", "--render-only", "--scenes", scenes.to_str().unwrap(), "--count", "2", "--out"];
    vkdiff(&[&args[..], &[out.to_str().unwrap()], extra].concat())
}

fn make_set(out: &Path, extra: &[&str]) {
    let run = dataset_of_two(out, extra);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
}

#[test]
fn controls_are_the_numpy_ones_recorded_and_previewed() {
    let dir = scratch("controls");
    let set = dir.join("set");
    make_set(&set, &["--controls", "edges,segmentation", "--controls", "normals"]);
    let coco = read_json(&set.join("annotations.json"));
    for (image, scene) in coco["images"].as_array().unwrap().iter().zip(["orchard-a", "orchard-b"]) {
        let files = image["control_files"].as_object().unwrap();
        assert_eq!(files.keys().collect::<Vec<_>>(), ["edges", "normals", "segmentation"]);
        for (kind, file) in files {
            let file = file.as_str().unwrap();
            assert_eq!(file, image["control_file"].as_str().unwrap().replace(".png", &format!(".{kind}.png")));
            let ours = png_pixels(&set.join(file));
            let numpy = png_pixels(&fixtures().join("controls/folders").join(scene).join(format!("{kind}.png")));
            let worst = ours.iter().zip(&numpy).map(|(a, b)| a.abs_diff(*b)).max().unwrap();
            let allowed = if kind == "normals" { 1 } else { 0 };
            assert!(ours.len() == numpy.len() && worst <= allowed, "{scene} {kind}: off by {worst}");
        }
    }
    let settings = read_json(&set.join("dataset.json"));
    let recorded = settings.to_string();
    assert!(
        recorded.contains("\"edge-depth-jump\":0.05") && recorded.contains("control/NNNNNN.<kind>.png"),
        "{recorded}"
    );
    // Resuming with other controls is refused, naming the flag.
    let other = dataset_of_two(&set, &["--controls", "edges"]);
    assert_eq!(other.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&other.stderr).contains("--controls"),
        "{}",
        String::from_utf8_lossy(&other.stderr)
    );

    // The preview shows each control as a layer.
    let html = dir.join("page.html");
    let preview = vkdiff(&["dataset", "preview", set.to_str().unwrap(), "--out", html.to_str().unwrap()]);
    assert!(preview.status.success(), "{}", String::from_utf8_lossy(&preview.stderr));
    let page = std::fs::read_to_string(&html).unwrap();
    for kind in ["edges", "normals", "segmentation"] {
        assert!(page.contains(&format!("value=\"control-{kind}\"")) && page.contains(&format!("img.control-{kind}")));
    }
    let browser = chromium();
    let url = format!("file://{}", html.display());
    let shot =
        |layer: &str| screenshot(&browser, &format!("{url}#{layer},nooutlines"), &dir.join(format!("{layer}.png")));
    let (image, edges, segmentation) = (shot("image"), shot("control-edges"), shot("control-segmentation"));
    let share = |pixels: &[[u8; 3]], colour: [u8; 3]| pixels.iter().filter(|&&p| p == colour).count();
    assert!(share(&edges, [255, 255, 255]) > 2000, "no edge lines on the edges layer");
    assert!(share(&image, [255, 255, 255]) < share(&edges, [255, 255, 255]) / 10, "the image layer shows lines");
    let colours = &settings["settings"]["segmentation-colours"];
    let apple: Vec<u8> = colours[0]["rgb"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap() as u8).collect();
    assert!(share(&segmentation, [apple[0], apple[1], apple[2]]) > 2000, "no apples on the segmentation layer");
}

#[test]
fn a_set_without_controls_has_none_and_bad_values_are_refused() {
    let dir = scratch("no-controls");
    let set = dir.join("set");
    make_set(&set, &[]);
    let coco = read_json(&set.join("annotations.json"));
    assert!(coco["images"].as_array().unwrap().iter().all(|i| i.get("control_files").is_none()));
    let listed: Vec<String> = std::fs::read_dir(set.join("control"))
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into())
        .collect();
    assert!(listed.iter().all(|n| n.matches('.').count() == 1), "{listed:?}");
    assert!(!read_json(&set.join("dataset.json")).to_string().contains("controls"));
    for (flags, needle) in [
        (["--controls", "canny"], "expected one of depth, edges, segmentation, normals"),
        (["--edge-depth-jump", "0"], "--edge-depth-jump 0 must be a positive fraction"),
    ] {
        let out = dir.join(format!("bad{}", flags[0]));
        let run = dataset_of_two(&out, &flags);
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "{flags:?}: {stderr}");
        assert!(stderr.contains(needle) && !out.exists(), "{flags:?}: {stderr}");
    }
}

#[test]
fn the_renderers_normals_make_the_normals_control() {
    // BlenderProc frames with `normals`, and a scene folder with normals.exr: whole frames (their
    // sides are multiples of 8), the control the numpy one made from the renderer's normals.
    for (format, scenes) in [("blenderproc", vec!["0", "1"]), ("folders", vec!["orchard-n"])] {
        let set = scratch(&format!("given-normals-{format}")).join("set");
        let dir = fixtures().join("scenes/normals").join(format);
        let args = ["dataset", "--render-only", "--scenes", dir.to_str().unwrap(), "--controls", "normals", "--out"];
        let run = vkdiff(&[&args[..], &[set.to_str().unwrap()]].concat());
        assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
        let coco = read_json(&set.join("annotations.json"));
        assert_eq!(coco["images"].as_array().unwrap().len(), scenes.len());
        for (image, scene) in coco["images"].as_array().unwrap().iter().zip(&scenes) {
            let ours = png_pixels(&set.join(image["control_files"]["normals"].as_str().unwrap()));
            let numpy = png_pixels(&fixtures().join("controls/normals").join(format).join(scene).join("normals.png"));
            let worst = ours.iter().zip(&numpy).map(|(a, b)| a.abs_diff(*b)).max().unwrap();
            assert!(ours.len() == numpy.len() && worst == 0, "{format}/{scene}: off by {worst}");
        }
    }
}
