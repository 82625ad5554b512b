//! `vkdiff dataset audit` on a render-only set with faults planted in it: objects painted over
//! with background (and left out of the predictions), detections added over background, masks
//! shifted off their objects. Each kind's flags are held to what was planted (precision and
//! recall, printed for docs/dataset-audit.md) and shown by `dataset preview --flagged`; bad
//! predictions files are refused in one line; exports leave the flagged images out (exports.rs).

mod cli;
#[path = "dataset_audit_cli/exports.rs"]
mod exports;

use cli::{layer_pngs, render_set_of, rgba, scratch, vkdiff};
use serde_json::{json, Value};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Output;
use vkdiff_render::rle::{PixelBox, Rle};

fn read_json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn mask_of(a: &Value) -> Rle {
    let s = &a["segmentation"];
    let (h, w) = (s["size"][0].as_u64().unwrap() as u32, s["size"][1].as_u64().unwrap() as u32);
    Rle::from_coco_string(s["counts"].as_str().unwrap(), h, w).unwrap()
}

fn encode(mask: &[bool], w: u32, h: u32) -> Value {
    let rle = Rle::from_labels(mask, w, h, true, PixelBox { x0: 0, y0: 0, x1: w - 1, y1: h - 1 });
    json!({"size": [h, w], "counts": rle.to_coco_string()})
}

/// The set's own labels as a detector's masks, score 0.9.
fn as_result(a: &Value) -> Value {
    json!({"image_id": a["image_id"], "category_id": a["category_id"], "segmentation": a["segmentation"], "bbox": a["bbox"], "score": 0.9})
}

/// Fills the pixels of `mask` from the outside in, each the mean of its filled 4-neighbours, as
/// an inpainting that leaves no edge where the object was.
fn paint_over(rgb: &mut [u8], mask: &[bool], w: usize) {
    let mut open: Vec<bool> = mask.to_vec();
    while open.iter().any(|&o| o) {
        let ring: Vec<(usize, [u8; 3])> = (0..open.len())
            .filter(|&p| open[p])
            .filter_map(|p| {
                let near = [(p % w > 0).then(|| p - 1), (p % w + 1 < w).then(|| p + 1), p.checked_sub(w), Some(p + w)];
                let known: Vec<usize> = near.into_iter().flatten().filter(|&q| q < open.len() && !open[q]).collect();
                (!known.is_empty()).then(|| {
                    let mean =
                        |c: usize| (known.iter().map(|&q| rgb[q * 3 + c] as usize).sum::<usize>() / known.len()) as u8;
                    (p, [mean(0), mean(1), mean(2)])
                })
            })
            .collect();
        assert!(!ring.is_empty(), "a mask with nothing around it");
        for (p, colour) in ring {
            rgb[p * 3..p * 3 + 3].copy_from_slice(&colour);
            open[p] = false;
        }
    }
}

/// Precision and recall of `flagged` against `planted`.
fn precision_recall(flagged: &BTreeSet<u64>, planted: &BTreeSet<u64>) -> (f64, f64) {
    let hit = flagged.intersection(planted).count() as f64;
    (hit / flagged.len().max(1) as f64, hit / planted.len().max(1) as f64)
}

/// The flags a detector's predictions give hold exactly what was planted.
fn assert_exact(rows: &[(&str, f64, f64, usize)]) {
    for (kind, p, r, _) in &rows[..3] {
        assert_eq!((*p, *r), (1.0, 1.0), "{kind}");
    }
}

/// The same faults in a set made by the tiny SDXL and ControlNet (random weights: noise images,
/// so only the predictions' flags are held).
#[test]
fn planted_faults_are_found_in_a_tiny_model_set() {
    let root = scratch("audit-planted-tiny");
    let set = root.join("set");
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures");
    let out = vkdiff(&[
        "dataset",
        "--out",
        set.to_str().unwrap(),
        "--count",
        "4",
        "--width",
        "384",
        "--height",
        "256",
        "--crops",
        "2",
        "--crop-size",
        "192",
        "--seed",
        "11",
        "--steps",
        "2",
        "--prompt",
        "mushrooms",
        "--model",
        fixtures.join("pipeline/tiny-sdxl").to_str().unwrap(),
        "--controlnet",
        fixtures.join("workflow/controlnet").to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let planted = planted_in(set, &root);
    let counts = (planted.painted.len(), planted.shifted.len(), planted.invented.len());
    assert!(counts.0 >= 4 && counts.1 >= 4 && counts.2 >= 2, "painted, shifted, invented: {counts:?}");
    assert_exact(&found(&planted).0);
}

/// A render-only set with faults planted, and predictions on it.
struct Planted {
    set: PathBuf,
    predictions: PathBuf,
    painted: BTreeSet<u64>,
    shifted: BTreeSet<u64>,
    /// The images given a detection over background.
    invented: BTreeSet<u64>,
}

/// 12 objects painted over with what surrounds them (and left out of the predictions), 18
/// labels shifted 5 pixels off their objects, 4 detections added over background; the
/// predictions otherwise the labels themselves.
fn planted(root: &Path) -> Planted {
    let set = root.join("set");
    render_set_of(&set, 4, 384, 256, 192);
    let planted = planted_in(set, root);
    let Planted { painted, shifted, invented, .. } = &planted;
    assert!(painted.len() >= 8 && shifted.len() >= 8 && invented.len() >= 3, "{painted:?} {shifted:?} {invented:?}");
    planted
}

/// The faults of [`planted`] put into the finished set `set` (of eight images or more).
fn planted_in(set: PathBuf, root: &Path) -> Planted {
    let coco_path = set.join("annotations.json");
    let mut coco = read_json(&coco_path);
    let images: Vec<Value> = coco["images"].as_array().unwrap().clone();
    let mut results = Vec::new();
    let (mut painted, mut shifted, mut invented) = (BTreeSet::new(), BTreeSet::new(), BTreeSet::new());
    for (k, image) in images.iter().enumerate() {
        let (w, h) = (image["width"].as_u64().unwrap() as usize, image["height"].as_u64().unwrap() as usize);
        let id = image["id"].clone();
        let path = set.join(image["file_name"].as_str().unwrap());
        let mut rgb = vkdiff_formats::image::read_image(&path).unwrap().pixels;
        let anns: Vec<&mut Value> =
            coco["annotations"].as_array_mut().unwrap().iter_mut().filter(|a| a["image_id"] == id).collect();
        let mut labelled = vec![false; w * h];
        for a in &anns {
            mask_of(a).to_mask().iter().enumerate().filter(|(_, on)| **on).for_each(|(p, _)| labelled[p] = true);
        }
        let mut big = 0;
        for a in anns {
            let large = a["area"].as_u64().unwrap() >= 150;
            let aid = a["id"].as_u64().unwrap();
            if large && big < 3 && k < 4 {
                // Painted over with what surrounds it; the detector finds nothing there.
                big += 1;
                paint_over(&mut rgb, &mask_of(a).to_mask(), w);
                painted.insert(aid);
                continue;
            }
            results.push(as_result(a));
            if large && big < 6 && (2..6).contains(&k) {
                // The label moved 5 pixels right of its object; the detector still sees the object.
                big += 1;
                let mask = mask_of(a).to_mask();
                let mut moved = vec![false; w * h];
                for (p, _) in mask.iter().enumerate().filter(|(p, on)| **on && p % w + 5 < w) {
                    moved[p + 5] = true;
                }
                a["segmentation"] = encode(&moved, w as u32, h as u32);
                a["bbox"][0] = json!(a["bbox"][0].as_f64().unwrap() + 5.0);
                shifted.insert(aid);
            }
        }
        std::fs::write(&path, vkdiff_render::png_out::rgb8(w as u32, h as u32, &rgb)).unwrap();
        if k >= 4 {
            // A detection over a background patch no label touches.
            let spot = (0..h - 12)
                .flat_map(|y| (0..w - 12).map(move |x| (x, y)))
                .find(|&(x, y)| (y..y + 12).all(|v| (x..x + 12).all(|u| !labelled[v * w + u])));
            if let Some((x, y)) = spot {
                results.push(json!({"image_id": id, "category_id": 1, "bbox": [x, y, 12, 12], "score": 0.8,
                    "segmentation": [[x, y, x + 12, y, x + 12, y + 12, x, y + 12]]}));
                invented.insert(id.as_u64().unwrap());
            }
        }
    }
    std::fs::write(&coco_path, coco.to_string()).unwrap();
    let predictions = root.join("predictions.json");
    std::fs::write(&predictions, Value::from(results).to_string()).unwrap();
    Planted { set, predictions, painted, shifted, invented }
}

/// Audits a planted set; per fault, the flag's precision and recall (printed) and the audit.
fn found(planted: &Planted) -> (Vec<(&'static str, f64, f64, usize)>, Value) {
    let Planted { set, predictions, painted, shifted, invented } = planted;
    let out =
        vkdiff(&["dataset", "audit", set.to_str().unwrap(), "--predictions", predictions.to_str().unwrap(), "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let audit = read_json(&set.join("audit.json"));
    let flagged = |kind: &str| -> BTreeSet<u64> {
        let instances = audit["images"].as_array().unwrap().iter().flat_map(|i| i["worst"].as_array().unwrap());
        instances
            .filter(|a| a["flags"].as_array().unwrap().iter().any(|f| f == kind))
            .map(|a| a["id"].as_u64().unwrap())
            .collect()
    };
    let invented_images: BTreeSet<u64> = audit["images"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|i| !i["invented"].as_array().unwrap().is_empty())
        .map(|i| i["id"].as_u64().unwrap())
        .collect();
    // Precision: the share of an instance flag that fell on a planted fault (a shifted label
    // may read as missing as well as a poor mask); recall: the share of a fault's plants found.
    let faulty: BTreeSet<u64> = painted.union(shifted).copied().collect();
    let found_shifted: BTreeSet<u64> = flagged("poor_mask").union(&flagged("missing")).copied().collect();
    let precision = |kind: &str| precision_recall(&flagged(kind), &faulty).0;
    let rows = [
        (
            "missing (painted over)",
            precision("missing"),
            precision_recall(&flagged("missing"), painted).1,
            painted.len(),
        ),
        (
            "invented (added)",
            precision_recall(&invented_images, invented).0,
            precision_recall(&invented_images, invented).1,
            invented.len(),
        ),
        (
            "poor_mask or missing (shifted 5 px)",
            precision("poor_mask"),
            precision_recall(&found_shifted, shifted).1,
            shifted.len(),
        ),
        (
            "weak_boundary (painted or shifted)",
            precision("weak_boundary"),
            precision_recall(&flagged("weak_boundary"), &faulty).1,
            faulty.len(),
        ),
    ];
    for (kind, p, r, n) in rows {
        println!("{kind}: {n} planted, precision {p:.3}, recall {r:.3}");
    }
    (rows.to_vec(), audit)
}

#[test]
fn planted_faults_are_found() {
    let root = scratch("audit-planted");
    let planted = planted(&root);
    let (rows, audit) = found(&planted);
    let set = &planted.set;
    // What a detector's predictions say is exact; the edges are a heuristic, held to a floor.
    assert_exact(&rows);
    let (_, p, r, _) = rows[3];
    assert!(p >= 0.9 && r >= 0.5, "weak_boundary: precision {p}, recall {r}");

    // The preview of the flagged images only, each with red outlines or boxes.
    let html = root.join("flagged.html");
    let out = vkdiff(&["dataset", "preview", set.to_str().unwrap(), "--flagged", "--out", html.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let page = std::fs::read_to_string(&html).unwrap();
    let flagged_images = audit["summary"]["flagged"]["images"].as_u64().unwrap();
    assert!(page.contains(&format!("of {flagged_images} flagged images")), "the page's title");
    let outlines = layer_pngs(&page, "outline");
    assert_eq!(outlines.len() as u64, flagged_images.min(24));
    for png in &outlines {
        assert!(rgba(png).1.contains(&[255, 0, 0, 255]), "a flagged image with nothing in the warning colour");
    }
}

/// Runs vkdiff, which must succeed.
fn run_ok(args: &[&str]) {
    let out = vkdiff(args);
    assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
}

/// `vkdiff dataset export SET --format FORMAT --out OUT`, then `extra`.
fn export(set: &Path, out: &Path, format: &str, extra: &[&str]) -> Output {
    let args = ["dataset", "export", set.to_str().unwrap(), "--format", format, "--out", out.to_str().unwrap()];
    vkdiff(&[&args[..], extra].concat())
}

/// `v` with `key` set to `value`.
fn with(v: &Value, key: &str, value: Value) -> Value {
    let mut v = v.clone();
    v[key] = value;
    v
}

#[test]
fn bad_predictions_are_refused_in_one_line_before_any_work() {
    let root = scratch("audit-refusals");
    let set = root.join("set");
    render_set_of(&set, 1, 128, 96, 96);
    let coco = read_json(&set.join("annotations.json"));
    let good = as_result(&coco["annotations"][0]);
    for (name, content, message) in [
        ("malformed.json", "[{".to_string(), "not JSON"),
        ("object.json", "{}".to_string(), "not a results list"),
        (
            "unknown-image.json",
            json!([with(&good, "image_id", json!(999))]).to_string(),
            "image 999 is not in the ground truth",
        ),
        ("unknown-category.json", json!([with(&good, "category_id", json!(7))]).to_string(), "category 7"),
    ] {
        let path = root.join(name);
        std::fs::write(&path, content).unwrap();
        let out = vkdiff(&["dataset", "audit", set.to_str().unwrap(), "--predictions", path.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{name}: {err}");
        assert!(err.contains(message) && err.trim().lines().count() == 1, "{name}: {err}");
        assert!(!set.join("audit.json").exists(), "{name}: an audit was written");
    }
    let out = vkdiff(&["dataset", "preview", set.to_str().unwrap(), "--flagged"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("has no audit.json to show: run `vkdiff dataset audit"), "{err}");
    for (flag, message) in [
        ("--exclude-flagged", "has no audit.json to exclude by"),
        ("--exclude-flagged=painted", "no flag `painted`"),
        ("--min-boundary-score=2", "--min-boundary-score 2: it takes a number from 0 to 1"),
    ] {
        let out_dir = root.join("export");
        let out = export(&set, &out_dir, "coco", &[flag]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{flag}: {err}");
        assert!(err.contains(message) && err.trim().lines().count() == 1 && !out_dir.exists(), "{flag}: {err}");
    }
}
