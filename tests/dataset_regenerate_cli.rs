//! `vkdiff dataset … --regenerate-flagged`: on a set made by the tiny SDXL and ControlNet, the
//! image the audit flagged is made again with a new recorded seed and the others are kept byte
//! for byte; the same command run again resumes without a new round; a second audit shows the
//! difference; a render-only set is refused.

mod cli;

use cli::{scratch, vkdiff};
use serde_json::{json, Value};
use std::path::Path;

fn read_json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn run_ok(args: &[&str]) -> String {
    let out = vkdiff(args);
    assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Each image's entry, by id.
fn entries(set: &Path) -> Vec<Value> {
    read_json(&set.join("annotations.json"))["images"].as_array().unwrap().clone()
}

#[test]
fn flagged_images_are_made_again_with_new_seeds() {
    let root = scratch("regenerate");
    let set = root.join("set");
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures");
    let (model, controlnet) = (fixtures.join("pipeline/tiny-sdxl"), fixtures.join("workflow/controlnet"));
    let make = |extra: &[&str]| {
        let base = [
            "dataset",
            "--out",
            set.to_str().unwrap(),
            "--count",
            "1",
            "--width",
            "128",
            "--height",
            "96",
            "--crops",
            "2",
            "--crop-size",
            "64",
            "--seed",
            "3",
            "--steps",
            "2",
            "--prompt",
            "mushrooms",
            "--model",
            model.to_str().unwrap(),
            "--controlnet",
            controlnet.to_str().unwrap(),
        ];
        run_ok(&[&base[..], extra].concat())
    };
    make(&[]);
    let before = entries(&set);
    let coco = read_json(&set.join("annotations.json"));
    // The predictions miss one object of the first image: it alone is flagged missing.
    let first = coco["annotations"].as_array().unwrap().iter().position(|a| a["image_id"] == before[0]["id"]).unwrap();
    let results: Vec<Value> = coco["annotations"]
        .as_array()
        .unwrap()
        .iter()
        .enumerate()
        .filter(|(k, _)| *k != first)
        .map(|(_, a)| json!({"image_id": a["image_id"], "category_id": a["category_id"], "bbox": a["bbox"], "score": 0.9}))
        .collect();
    let predictions = root.join("predictions.json");
    std::fs::write(&predictions, Value::from(results).to_string()).unwrap();
    let audit = |name: &str| {
        run_ok(&["dataset", "audit", set.to_str().unwrap(), "--predictions", predictions.to_str().unwrap()]);
        std::fs::copy(set.join("audit.json"), root.join(name)).unwrap();
        read_json(&root.join(name))
    };
    let first_audit = audit("audit-1.json");
    let flagged: Vec<bool> = first_audit["images"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| i["flags"].as_array().unwrap().contains(&json!("missing")))
        .collect();
    assert_eq!(flagged, [true, false]);
    let (image_1, image_2) =
        (set.join(before[0]["file_name"].as_str().unwrap()), set.join(before[1]["file_name"].as_str().unwrap()));
    let (bytes_1, bytes_2) = (std::fs::read(&image_1).unwrap(), std::fs::read(&image_2).unwrap());

    let log = make(&["--regenerate-flagged=missing"]);
    assert!(log.contains("regenerating 1 images the audit flagged"), "{log}");
    let after = entries(&set);
    assert_eq!(after[0]["resample"], 1, "{}", after[0]);
    assert_ne!(after[0]["seed"], before[0]["seed"]);
    assert_ne!(std::fs::read(&image_1).unwrap(), bytes_1, "the flagged image was not made again");
    assert_eq!((&after[1], std::fs::read(&image_2).unwrap()), (&before[1], bytes_2.clone()), "the other image changed");
    assert_eq!(read_json(&set.join("resamples.json"))["rounds"], json!({"0": 1}));

    // The same command again: a resume, no new round.
    let log = make(&["--regenerate-flagged=missing"]);
    assert!(log.contains("resuming the regeneration of 1 images") && log.contains("0 to make"), "{log}");
    assert_eq!(entries(&set), after);

    // A second audit sees the new image: its boundary score moved, the other's did not.
    let second_audit = audit("audit-2.json");
    let f = |a: &Value, k: usize| a["images"][k]["boundary"]["f"].as_f64();
    assert_ne!(f(&first_audit, 0), f(&second_audit, 0));
    assert_eq!(f(&first_audit, 1), f(&second_audit, 1));
    // It is still flagged (the predictions are the same file): a second round, another seed.
    make(&["--regenerate-flagged=missing"]);
    let again = entries(&set);
    assert_eq!(again[0]["resample"], 2);
    assert!(again[0]["seed"] != after[0]["seed"] && again[0]["seed"] != before[0]["seed"]);
}

#[test]
fn a_render_only_set_has_nothing_to_regenerate() {
    let root = scratch("regenerate-render-only");
    let set = root.join("set");
    let args =
        ["dataset", "--render-only", "--out", set.to_str().unwrap(), "--count", "1", "--width", "96", "--height", "64"];
    run_ok(&args);
    run_ok(&["dataset", "audit", set.to_str().unwrap()]);
    let out = vkdiff(&[&args[..], &["--regenerate-flagged"]].concat());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("a --render-only set's images are its renders"), "{err}");
}
