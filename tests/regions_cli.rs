//! A prompt and a strength per category in `vkdiff dataset` over the orchard scene folders: the
//! masks and strengths made from each image's labels (the denoising itself is held to
//! tools/make_regions_fixtures.py in pipeline/tests/regions.rs), recorded per image, shown by the
//! preview, taken from categories.json as from the flags; equal strengths everywhere give the
//! plain img2img set byte for byte; bad names and values refused in one line before any work.

mod cli;

use cli::{png_pixels, png_text, scratch, tree, vkdiff};
use serde_json::Value;
use std::path::{Path, PathBuf};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures")
}

fn read_json(path: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

/// A set of the first two orchard scenes (160×128) through the tiny SDXL, with `extra` flags.
fn make_set(scenes: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    let model = fixtures().join("pipeline/tiny-sdxl");
    let mut args = vec!["dataset", "--scenes", scenes.to_str().unwrap(), "--count", "2", "--steps", "4"];
    args.extend(["--model", model.to_str().unwrap(), "--prompt", "an orchard", "--out", out.to_str().unwrap()]);
    args.extend(extra);
    vkdiff(&args)
}

fn ok(run: std::process::Output) {
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
}

#[test]
fn prompts_and_strengths_per_category_are_made_recorded_and_previewed() {
    let dir = scratch("regions");
    let scenes = fixtures().join("scenes/folders");
    let set = dir.join("set");
    let flags = [
        "--category-prompt",
        "apple=a shiny red apple",
        "--category-prompt",
        "leaf=a green leaf",
        "--category-strength",
        "apple=0.3",
        "--background-strength",
        "0.9",
        "--init-strength",
        "0.6",
        "--region-feather",
        "2",
    ];
    ok(make_set(&scenes, &set, &flags));

    let settings = &read_json(&set.join("dataset.json"))["settings"];
    assert_eq!(settings["category-prompts"]["apple"], "a shiny red apple", "{settings}");
    assert_eq!(settings["category-strengths"], serde_json::json!({"apple": 0.3}), "{settings}");
    assert_eq!((settings["background-strength"].as_f64(), settings["init-strength"].as_f64()), (Some(0.9), Some(0.6)));
    assert_eq!(settings["region-feather"], 2);

    let coco = read_json(&set.join("annotations.json"));
    for image in coco["images"].as_array().unwrap() {
        assert_eq!(image["region_prompts"]["leaf"], "a green leaf", "{image}");
        let text = png_text(&set.join(image["file_name"].as_str().unwrap()));
        let get = |k: &str| text.iter().find(|(key, _)| key == k).map(|(_, v)| v.clone()).unwrap_or_default();
        assert_eq!(get("region_prompts"), "apple=a shiny red apple\nleaf=a green leaf");
        assert_eq!((get("category_strengths").as_str(), get("background_strength").as_str()), ("apple=0.3", "0.9"));
        assert_eq!(get("strength"), "0.9", "the schedule runs at the largest strength");

        // The strength map: each pixel's strength where its neighbourhood is one category.
        let file = image["strength_file"].as_str().expect("a strength file");
        assert_eq!(file, image["init_file"].as_str().unwrap().replace(".png", ".strength.png"));
        let strength = png_pixels(&set.join(file));
        let mask = png_pixels(&set.join(image["mask_file"].as_str().unwrap()));
        let ids: Vec<u16> = mask.chunks_exact(2).map(|b| u16::from_be_bytes([b[0], b[1]])).collect();
        let category_of = |id: u16| {
            let annotations = coco["annotations"].as_array().unwrap();
            let a = annotations.iter().find(|a| a["image_id"] == image["id"] && a["mask_id"] == id);
            a.map_or(0, |a| a["category_id"].as_u64().unwrap())
        };
        let (w, h) = (image["width"].as_u64().unwrap() as usize, image["height"].as_u64().unwrap() as usize);
        let want = |c: u64| -> f64 {
            match c {
                0 => 0.9,
                1 => 0.3,
                _ => 0.6,
            }
        };
        let mut checked = [0usize; 3];
        for y in 2..h - 2 {
            for x in 2..w - 2 {
                let c = category_of(ids[y * w + x]);
                let uniform = (y - 2..=y + 2).all(|v| (x - 2..=x + 2).all(|u| category_of(ids[v * w + u]) == c));
                if uniform {
                    let level = strength[(y * w + x) * 3];
                    let want = (want(c) * 255.0).round() as u8;
                    assert!(level.abs_diff(want) <= 1, "pixel {x},{y} of category {c}: {level}, not {want}");
                    checked[c.min(2) as usize] += 1;
                }
            }
        }
        assert!(checked.iter().all(|&n| n > 20), "too few pixels checked: {checked:?}");
    }

    // The preview shows the strength map as a layer and each image's region prompts.
    let html = dir.join("page.html");
    ok(vkdiff(&["dataset", "preview", set.to_str().unwrap(), "--out", html.to_str().unwrap()]));
    let page = std::fs::read_to_string(&html).unwrap();
    assert!(page.contains("value=\"control-strength\"") && page.contains("img.control-strength"));
    assert!(page.contains("apple: a shiny red apple") && page.contains("leaf: a green leaf"));
}

#[test]
fn equal_strengths_are_plain_img2img_and_categories_json_guides_like_the_flags() {
    let dir = scratch("regions-equal");
    let scenes = fixtures().join("scenes/folders");
    let (plain, equal) = (dir.join("plain"), dir.join("equal"));
    ok(make_set(&scenes, &plain, &["--init-strength", "0.6"]));
    let same = ["--init-strength", "0.6", "--category-strength", "apple=0.6", "--background-strength", "0.6"];
    ok(make_set(&scenes, &equal, &same));
    assert!(tree(&plain) == tree(&equal), "equal strengths differ from the plain img2img set");

    // The same prompt and strength from categories.json as from the flags: the same set.
    let copied = dir.join("scenes");
    for scene in ["orchard-a", "orchard-b"] {
        std::fs::create_dir_all(copied.join(scene)).unwrap();
        for entry in std::fs::read_dir(scenes.join(scene)).unwrap() {
            let path = entry.unwrap().path();
            std::fs::copy(&path, copied.join(scene).join(path.file_name().unwrap())).unwrap();
        }
        let path = copied.join(scene).join("categories.json");
        let mut categories = read_json(&path);
        for c in categories["categories"].as_array_mut().unwrap() {
            if c["name"] == "apple" {
                c["prompt"] = "a shiny red apple".into();
                c["strength"] = 0.3.into();
            }
        }
        std::fs::write(&path, serde_json::to_vec(&categories).unwrap()).unwrap();
    }
    let (by_file, by_flags) = (dir.join("by-file"), dir.join("by-flags"));
    ok(make_set(&copied, &by_file, &["--init-strength", "0.6"]));
    let flags = ["--init-strength", "0.6", "--category-prompt", "apple=a shiny red apple", "--category-strength"];
    ok(make_set(&copied, &by_flags, &[&flags[..], &["apple=0.3"]].concat()));
    let images = |set: &Path| tree(&set.join("images"));
    assert!(images(&by_file) == images(&by_flags), "categories.json's guides differ from the flags'");
    assert!(images(&by_file) != images(&plain), "the guides changed nothing");
}

#[test]
fn bad_region_flags_are_refused_in_one_line_before_any_work() {
    let dir = scratch("regions-bad");
    let scenes = fixtures().join("scenes/folders");
    let out = dir.join("set");
    for (flags, message) in [
        (vec!["--category-prompt", "pear=a pear"], "--category-prompt pear=: no such category"),
        (vec!["--category-strength", "apple=0"], "--category-strength apple=0 must be in (0, 1]"),
        (vec!["--category-strength", "apple=1.5"], "must be in (0, 1]"),
        (vec!["--background-strength", "2"], "--background-strength 2 must be in (0, 1]"),
        (vec!["--category-prompt", "apple="], "--category-prompt apple= is empty"),
        (vec!["--category-strength", "apple"], "expected NAME=TEXT"),
    ] {
        let result = make_set(&scenes, &out, &flags);
        let stderr = String::from_utf8_lossy(&result.stderr);
        let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
        assert!(result.status.code() == Some(2) && errors.len() == 1, "{flags:?}: {stderr}");
        assert!(errors[0].contains(message), "{flags:?}: {stderr}");
        assert!(!out.exists(), "{flags:?} wrote {}", out.display());
    }
    let render_only = vkdiff(&[
        "dataset",
        "--render-only",
        "--scenes",
        scenes.to_str().unwrap(),
        "--count",
        "2",
        "--category-prompt",
        "apple=x",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(render_only.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&render_only.stderr).contains("needs a model"));
}
