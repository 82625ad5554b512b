//! `vkdiff dataset --scenes` refusing what it cannot read, in one line naming it, exit 2, with
//! nothing written: scene folders missing a file, of mismatched sizes, a category id listed twice
//! or named two ways, an unreadable depth, a normals.exr without normals, none at all; and
//! BlenderProc frames broken one way each (tools/make_scene_fixtures.py writes them with h5py; a
//! stereo pair's `normals` among them). What only a scene's pixels show (an instance without a
//! category) stops the run at that scene, its images before it whole, and the run resumes once
//! the scene is mended.

mod cli;

use cli::{command, scratch, tree};
use serde_json::Value;
use std::path::{Path, PathBuf};

fn scenes(format: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/scenes").join(format)
}

fn read_json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The one `error:` line of a refused run, which must exit 2 and write nothing.
fn refusal(scenes_dir: &Path, extra: &[&str]) -> String {
    let out_dir = scenes_dir.parent().unwrap().join("never");
    let mut args =
        vec!["dataset", "--render-only", "--scenes", scenes_dir.to_str().unwrap(), "--out", out_dir.to_str().unwrap()];
    args.extend(extra);
    let out = command().args(&args).output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
    assert_eq!(errors.len(), 1, "{stderr}");
    assert!(!out_dir.exists(), "a refused run wrote {}", out_dir.display());
    errors[0].to_string()
}

/// A copy of the fixture's scene folders with `change` made to it.
fn changed(name: &str, change: &dyn Fn(&Path)) -> PathBuf {
    let dir = scratch(&format!("scenes-bad-{name}")).join("scenes");
    for scene in ["orchard-a", "orchard-b"] {
        let (from, to) = (scenes("folders").join(scene), dir.join(scene));
        std::fs::create_dir_all(&to).unwrap();
        for entry in std::fs::read_dir(&from).unwrap().flatten() {
            std::fs::copy(entry.path(), to.join(entry.file_name())).unwrap();
        }
    }
    change(&dir);
    dir
}

/// A change made to a copy of the scenes.
type Change = Box<dyn Fn(&Path)>;

#[test]
fn bad_scenes_are_refused_in_one_line_naming_them() {
    let cases: Vec<(&str, Change, &str)> = vec![
        (
            "missing",
            Box::new(|d: &Path| std::fs::remove_file(d.join("orchard-b/instances.png")).unwrap()),
            "scene orchard-b: instances.png:",
        ),
        (
            "size",
            Box::new(|d: &Path| {
                std::fs::copy(scenes("folders").join("orchard-c/instances.png"), d.join("orchard-b/instances.png"))
                    .unwrap();
            }),
            "scene orchard-b: instances.png: 192×144, the depth is 160×128",
        ),
        (
            "normals-channels",
            Box::new(|d: &Path| {
                std::fs::copy(d.join("orchard-b/depth.exr"), d.join("orchard-b/normals.exr")).unwrap();
            }),
            "scene orchard-b: normals.exr: no X, Y and Z channels (the camera-space normal); channels: ViewLayer.Depth.Z",
        ),
        (
            "twice",
            Box::new(|d: &Path| {
                let path = d.join("orchard-a/categories.json");
                let mut c = read_json(&path);
                c["categories"][1]["id"] = 1.into();
                std::fs::write(path, c.to_string()).unwrap();
            }),
            "scene orchard-a: categories.json: category id 1 is listed twice",
        ),
        (
            "unreadable",
            Box::new(|d: &Path| std::fs::write(d.join("orchard-b/depth.exr"), b"not an exr").unwrap()),
            "scene orchard-b:",
        ),
        (
            "renamed",
            Box::new(|d: &Path| {
                let path = d.join("orchard-b/categories.json");
                let mut c = read_json(&path);
                c["categories"][0]["name"] = "pear".into();
                std::fs::write(path, c.to_string()).unwrap();
            }),
            "category id 1 is `apple` in orchard-a and `pear` in orchard-b",
        ),
        (
            "camera-size",
            Box::new(|d: &Path| {
                let k = [[100.0, 0.0, 79.5], [0.0, 100.0, 63.5], [0.0, 0.0, 1.0]];
                let camera = serde_json::json!({"K": k, "width": 161, "height": 128});
                std::fs::write(d.join("orchard-b/camera.json"), camera.to_string()).unwrap();
            }),
            "scene orchard-b: camera.json: 161×128, the depth is 160×128",
        ),
        (
            "camera-skew",
            Box::new(|d: &Path| {
                let k = [[100.0, 3.0, 79.5], [0.0, 100.0, 63.5], [0.0, 0.0, 1.0]];
                let camera = serde_json::json!({"K": k, "width": 160, "height": 128});
                std::fs::write(d.join("orchard-b/camera.json"), camera.to_string()).unwrap();
            }),
            "scene orchard-b: camera.json: K [[100.0, 3.0, 79.5]",
        ),
        (
            "keypoint-visibility",
            Box::new(|d: &Path| std::fs::write(d.join("orchard-a/keypoints.json"), r#"{"5": [3, 4, 7]}"#).unwrap()),
            "scene orchard-a: keypoints.json: instance 5: [3.0, 4.0, 7.0] is not x, y and a visibility of 0, 1 or 2",
        ),
        (
            "keypoint-count",
            Box::new(|d: &Path| std::fs::write(d.join("orchard-a/keypoints.json"), r#"{"5": [3, 4, 2]}"#).unwrap()),
            "scene orchard-a: keypoints.json: instance 5: 1 keypoints; its category `apple` names 0 in categories.json",
        ),
        (
            "empty",
            Box::new(|d: &Path| std::fs::remove_dir_all(d).and_then(|_| std::fs::create_dir_all(d)).unwrap()),
            "holds no scene folders",
        ),
    ];
    for (name, change, needle) in cases {
        let dir = changed(name, &*change);
        let line = refusal(&dir, &[]);
        assert!(line.starts_with("error: --scenes") && line.contains(needle), "{name}: {line}");
    }
    let dir = scenes("folders");
    assert!(refusal(&dir, &["--count", "4"]).contains("--count 4: --scenes holds 3"));
    let out = command()
        .args(["dataset", "--render-only", "--scenes", dir.to_str().unwrap(), "--out", "x", "--width", "64"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "--scenes with the procedural bed's --width");
}

#[test]
fn broken_blenderproc_frames_are_refused_in_one_line_naming_them() {
    // tools/make_scene_fixtures.py writes each fault with h5py as BlenderProc's writer would.
    for (fault, needle) in [
        ("no-segmaps", "no `instance_segmaps`"),
        ("no-depth", "no `depth` or `distance`"),
        ("depth-shape", "`depth` has shape [39, 48], the segmentation 40×48"),
        ("idx-twice", "lists idx"),
        ("attributes-not-json", "`instance_attribute_maps` is not a list of {idx, category_id}"),
        ("stereo", "one H×W map per file"),
        ("truncated", "cut short: 6222 bytes, where its HDF5 superblock says 12444"),
        ("../normals/blenderproc-bad/normals-shape", "`normals` has shape [2, 112, 144, 3]; expected 112×144×3"),
    ] {
        let copy = scratch(&format!("blenderproc-bad-{}", fault.rsplit('/').next().unwrap())).join("scenes");
        std::fs::create_dir_all(&copy).unwrap();
        std::fs::copy(scenes("blenderproc-bad").join(fault).join("0.hdf5"), copy.join("0.hdf5")).unwrap();
        let line = refusal(&copy, &[]);
        assert!(
            line.starts_with("error: --scenes") && line.contains("0.hdf5") && line.contains(needle),
            "{fault}: {line}"
        );
    }
}

/// orchard-b's categories.json without the category of its first instance.
fn drop_first_instance(dir: &Path) {
    let path = dir.join("orchard-b/categories.json");
    let mut c = read_json(&path);
    let first = c["instances"].as_object().unwrap().keys().next().unwrap().clone();
    c["instances"].as_object_mut().unwrap().remove(&first);
    std::fs::write(path, c.to_string()).unwrap();
}

#[test]
fn an_instance_without_a_category_stops_the_run_at_its_scene() {
    // Listing reads headers and side files only; the instance map is read once, for the images.
    let dir = changed("no-category", &drop_first_instance);
    let out_dir = dir.parent().unwrap().join("set");
    let args = ["dataset", "--render-only", "--scenes", dir.to_str().unwrap(), "--out", out_dir.to_str().unwrap()];
    let out = command().args(args).output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert_eq!(errors.len(), 1, "{stderr}");
    assert!(errors[0].contains("scene orchard-b") && errors[0].contains("has no category"), "{}", errors[0]);
    // orchard-a's image is whole; nothing of orchard-b's, and no set-wide annotations yet.
    let written = tree(&out_dir);
    for file in ["records/000000.json", "images/000000.png", "masks/000000.png"] {
        assert!(written.contains_key(file), "{file} missing: {:?}", written.keys());
    }
    assert!(written.keys().all(|f| !f.contains("000001") && !f.contains(".tmp")), "{:?}", written.keys());
    assert!(!written.contains_key("annotations.json"));
    // Mended, the run resumes into the set one clean run makes.
    std::fs::copy(scenes("folders").join("orchard-b/categories.json"), dir.join("orchard-b/categories.json")).unwrap();
    assert!(command().args(args).status().unwrap().success());
    let clean_dir = dir.parent().unwrap().join("clean");
    let clean = ["dataset", "--render-only", "--scenes", dir.to_str().unwrap(), "--out", clean_dir.to_str().unwrap()];
    assert!(command().args(clean).status().unwrap().success());
    assert!(tree(&out_dir) == tree(&clean_dir), "the resumed set differs from a clean run's");
}

#[test]
fn broken_bop_scenes_are_refused_in_one_line_naming_the_file() {
    // tools/make_bop_fixtures.py writes each fault; the refusal comes before any image is made.
    for (fault, needle) in [
        ("missing-mask", "scene 000000/000001: mask_visib/000001_000002.png: missing"),
        ("depth-size", "scene 000000/000001: rgb/000001.png: 96×72, its depth/ image is 95×72"),
    ] {
        let copy = scratch(&format!("bop-bad-{fault}")).join("scenes");
        for entry in walk(&scenes("bop-bad").join(fault)) {
            let to = copy.join(entry.strip_prefix(scenes("bop-bad").join(fault)).unwrap());
            std::fs::create_dir_all(to.parent().unwrap()).unwrap();
            std::fs::copy(&entry, to).unwrap();
        }
        let line = refusal(&copy, &[]);
        assert!(line.starts_with("error: --scenes") && line.contains(needle), "{fault}: {line}");
    }
    // A scene with mask/ missing one amodal mask; a dataset whose models_info.json is not BOP's.
    let copy_of = |from: &Path, name: &str| {
        let copy = scratch(name).join("dataset");
        for entry in walk(from) {
            let to = copy.join(entry.strip_prefix(from).unwrap());
            std::fs::create_dir_all(to.parent().unwrap()).unwrap();
            std::fs::copy(&entry, to).unwrap();
        }
        copy
    };
    let amodal = copy_of(&scenes("bop-dataset"), "bop-no-amodal");
    std::fs::remove_file(amodal.join("train_pbr/000000/mask/000001_000003.png")).unwrap();
    let line = refusal(&amodal.join("train_pbr"), &[]);
    assert!(line.contains("scene 000000/000001: mask/000001_000003.png: missing"), "{line}");
    let models = copy_of(&scenes("bop-dataset"), "bop-bad-models");
    std::fs::write(models.join("models/models_info.json"), r#"{"1": {"min_x": 0, "size_x": 1}}"#).unwrap();
    let line = refusal(&models.join("train_pbr"), &[]);
    assert!(line.contains("models_info.json: not BOP's models_info: missing field `min_y`"), "{line}");
    // A folder holding two layouts, and one holding none, name what was looked for.
    let mixed = scratch("bop-mixed").join("scenes");
    std::fs::create_dir_all(mixed.join("000000")).unwrap();
    for file in ["scene_camera.json", "scene_gt.json"] {
        std::fs::copy(scenes("bop/000000").join(file), mixed.join("000000").join(file)).unwrap();
    }
    std::fs::copy(scenes("blenderproc/0.hdf5"), mixed.join("0.hdf5")).unwrap();
    let line = refusal(&mixed, &[]);
    assert!(line.contains("BlenderProc .hdf5 files and BOP scene folders; one layout per folder"), "{line}");
    let empty = scratch("bop-none").join("scenes");
    std::fs::create_dir_all(empty.join("models")).unwrap();
    let line = refusal(&empty, &[]);
    assert!(line.contains("no BOP scenes (folders with scene_camera.json and scene_gt.json"), "{line}");
}

/// Every file under `dir`.
fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap().flatten() {
        let path = entry.path();
        if path.is_dir() {
            files.extend(walk(&path));
        } else {
            files.push(path);
        }
    }
    files
}

#[test]
fn broken_replicator_frames_are_refused_in_one_line_naming_the_file() {
    // tools/make_replicator_fixtures.py writes each fault; the refusal comes before any image is
    // made (an unlisted colour, which only the pixels show, is scenes/tests/replicator.rs's).
    for (fault, needle) in [
        ("missing-semantics", "frame 0001: instance_segmentation_semantics_mapping_0001.json: missing"),
        ("depth-size", "scene 0001: rgb_0001.png: 80×60, the frame's depth is 79×60"),
        ("depth-dtype", "scene 0000: distance_to_image_plane_0000.npy: dtype <i4; distance_to_image_plane is float32"),
        ("depth-3d", "scene 0000: distance_to_image_plane_0000.npy: shape [60, 80, 1]"),
        ("mixed", "holds BlenderProc .hdf5 files and Replicator BasicWriter frames; one layout per folder"),
        ("missing-box", "frame 0001: bounding_box_3d_0001.npy: missing"),
        ("box-dtype", "frame 0000: bounding_box_3d_0000.npy: dtype [semanticId <u4, x_min <f4"),
    ] {
        let copy = scratch(&format!("replicator-bad-{fault}")).join("scenes");
        std::fs::create_dir_all(&copy).unwrap();
        for entry in walk(&scenes("replicator-bad").join(fault)) {
            std::fs::copy(&entry, copy.join(entry.file_name().unwrap())).unwrap();
        }
        let line = refusal(&copy, &[]);
        assert!(line.starts_with("error: --scenes") && line.contains(needle), "{fault}: {line}");
    }
}

#[test]
fn broken_solo_steps_are_refused_in_one_line_naming_the_file() {
    // tools/make_solo_fixtures.py writes each fault; the refusal comes before any image is made
    // (an unlisted colour, which only the pixels show, is scenes/tests/solo.rs's).
    for (fault, needle) in [
        (
            "missing-png",
            "scene sequence.0/step1: step1.camera.instance segmentation.png: missing (step1.frame_data.json names it)",
        ),
        ("wrong-size", "scene sequence.0/step0: step0.camera.instance segmentation.png: 47×40, the depth is 48×40"),
        ("bad-json", "scene sequence.0/step1: step1.frame_data.json: not SOLO's frame data"),
        ("no-depth", "scene sequence.0/step0: step0.frame_data.json: capture `camera` has no DepthAnnotation"),
        ("label-clash", "labelId 1 is `Crate` in sequence.0/step0 and `Barrel` in sequence.1/step0.camera"),
        ("mixed", "holds BlenderProc .hdf5 files and Unity Perception SOLO sequences; one layout per folder"),
    ] {
        let from = scenes("solo-bad").join(fault);
        let copy = scratch(&format!("solo-bad-{fault}")).join("dataset");
        for entry in walk(&from) {
            let to = copy.join(entry.strip_prefix(&from).unwrap());
            std::fs::create_dir_all(to.parent().unwrap()).unwrap();
            std::fs::copy(&entry, to).unwrap();
        }
        let line = refusal(&copy, &[]);
        assert!(line.starts_with("error: --scenes") && line.contains(needle), "{fault}: {line}");
    }
}

#[test]
fn broken_kubric_frames_are_refused_in_one_line_naming_the_file() {
    // tools/make_kubric_fixtures.py writes each fault (the folder given is the sequence, but for
    // mixed); the refusal comes before any image is made (an index past the instances, which
    // only the pixels show, is scenes/tests/kubric.rs's).
    for (fault, needle) in [
        ("missing-tiff", "scene missing-tiff/00001: depth_00001.tiff: missing (metadata.json says the frame is there)"),
        ("wrong-size", "scene wrong-size/00000: segmentation_00000.png: 47×40, metadata.json's resolution is 48×40"),
        ("bad-metadata", "bad-metadata: metadata.json: not Kubric's metadata"),
        ("frame-count", "frame-count: metadata.json: camera.positions has 1 frames, metadata.num_frames says 2"),
        ("float-depth", "scene float-depth/00000: depth_00000.tiff: Gray(16) unsigned, not the one-channel float32"),
        ("mixed", "holds BlenderProc .hdf5 files and Kubric sequences; one layout per folder"),
    ] {
        let from = scenes("kubric-bad").join(fault);
        let copy = scratch(&format!("kubric-bad-{fault}")).join(fault);
        for entry in walk(&from) {
            let to = copy.join(entry.strip_prefix(&from).unwrap());
            std::fs::create_dir_all(to.parent().unwrap()).unwrap();
            std::fs::copy(&entry, to).unwrap();
        }
        let line = refusal(&copy, &[]);
        assert!(line.starts_with("error: --scenes") && line.contains(needle), "{fault}: {line}");
    }
}
