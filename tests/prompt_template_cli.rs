//! Prompt templates from the command line: a dataset of the tiny SDXL over the orchard scene
//! folders (categories apple, leaf, branch) whose prompt is a template with choices, category
//! slots and wildcards read from a folder; each image's expansion and choices recorded as the
//! library makes them from its seed and its crop's categories, whatever the batch, counted by
//! `dataset stats`, and the image reproduced by `vkdiff gen` from its expanded prompt; a template
//! in `vkdiff gen`; a resume with changed wildcard files, and every template refusal, one line
//! and exit code 2 with nothing written.

mod cli;

use cli::{command, png_text, scratch, tree};
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Output;
use vkdiff_pipeline::{CategorySlots, PromptTemplate, Wildcards};
use vkdiff_render::coco::Category;

const TEMPLATE: &str = "{2::a {category} close-up|some {categories}} on __soil__, __light/kind__";
/// orchard-a's prompt.txt: its images take it, as written.
const OWN_PROMPT: &str = "ripe red apples among green leaves on a branch";

fn fixture(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures").join(path)
}

fn run(args: &[&str]) -> Output {
    command().args(args).env("RUST_BACKTRACE", "0").output().unwrap()
}

fn run_ok(args: &[&str]) -> String {
    let out = run(args);
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{args:?}: {text}");
    text
}

/// The one error line of a run that must exit 2.
fn refused(args: &[&str]) -> String {
    let out = run(args);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
    assert_eq!(errors.len(), 1, "{args:?}: {stderr}");
    errors[0].to_string()
}

fn read_json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// A wildcards folder: soil.txt (a comment, a blank line, a line with choices) and light/kind.txt.
fn wildcards(root: &Path) -> PathBuf {
    let dir = root.join("wildcards");
    std::fs::create_dir_all(dir.join("light")).unwrap();
    std::fs::write(dir.join("soil.txt"), "# soils\ndark compost\n\n  {wet|dry} loam  \n").unwrap();
    std::fs::write(dir.join("light/kind.txt"), "soft light\nhard light\n").unwrap();
    dir
}

/// The dataset's flags: the orchard scenes, two 64² crops each, the tiny SDXL at 2 steps.
fn dataset_args(out: &str, wildcards: &str, model: &str) -> Vec<String> {
    let scenes = fixture("scenes/folders").display().to_string();
    [
        "dataset",
        "--out",
        out,
        "--scenes",
        &scenes,
        "--crops",
        "2",
        "--crop-size",
        "64",
        "--seed",
        "9",
        "--model",
        model,
        "--steps",
        "2",
        "--prompt",
        TEMPLATE,
        "--wildcards",
        wildcards,
    ]
    .map(String::from)
    .to_vec()
}

fn strs(args: &[String]) -> Vec<&str> {
    args.iter().map(String::as_str).collect()
}

#[test]
fn a_dataset_records_each_expansion_counts_its_choices_and_gen_reproduces_it() {
    let root = scratch("prompt-template-dataset");
    let dir = wildcards(&root);
    let set = root.join("set");
    let model = fixture("pipeline/tiny-sdxl");
    let (set_s, dir_s, model_s) = (set.to_str().unwrap(), dir.to_str().unwrap(), model.to_str().unwrap());
    run_ok(&strs(&dataset_args(set_s, dir_s, model_s)));
    // In batches of two, the expansions encoded as they come: the very same folder.
    let batched = root.join("batched");
    let mut args = dataset_args(batched.to_str().unwrap(), dir_s, model_s);
    args.extend(["--batch", "2"].map(String::from));
    run_ok(&strs(&args));
    assert!(tree(&set) == tree(&batched), "--batch 2 gives the same folder");

    let manifest = read_json(&set.join("dataset.json"));
    assert_eq!(manifest["settings"]["wildcards"], dir_s);
    assert!(manifest["settings"]["wildcards-hash"].as_str().is_some_and(|h| h.len() == 16), "{manifest}");

    // Each image's prompt is the template expanded by the library from its seed and its crop's
    // categories; orchard-a's images take its own prompt and record no template.
    let coco = read_json(&set.join("annotations.json"));
    let categories: Vec<Category> = serde_json::from_value(coco["categories"].clone()).unwrap();
    let template = PromptTemplate::parse(TEMPLATE).unwrap();
    let loaded = Wildcards::load(Some(&dir), &[&template]).unwrap();
    let mut choices: BTreeMap<String, BTreeMap<String, u64>> = BTreeMap::new();
    let mut prompts: BTreeMap<String, u64> = BTreeMap::new();
    let mut templated = Vec::new();
    for image in coco["images"].as_array().unwrap() {
        let prompt = image["prompt"].as_str().unwrap();
        *prompts.entry(prompt.to_string()).or_default() += 1;
        if image["scene"] == "orchard-a" {
            assert_eq!(prompt, OWN_PROMPT);
            assert!(image.get("prompt_template").is_none() && image.get("prompt_choices").is_none(), "{image}");
            continue;
        }
        let of_image = coco["annotations"].as_array().unwrap().iter().filter(|a| a["image_id"] == image["id"]);
        let ids: Vec<u32> = of_image.map(|a| a["category_id"].as_u64().unwrap() as u32).collect();
        let slots = CategorySlots::new(ids, &categories);
        let want = template.expand(image["seed"].as_u64().unwrap(), &loaded, Some(&slots)).unwrap();
        assert_eq!(prompt, want.prompt, "{image}");
        assert_eq!(image["prompt_template"], TEMPLATE);
        let recorded = image["prompt_choices"].as_array().unwrap();
        assert_eq!(recorded.len(), want.choices.len());
        for (r, w) in recorded.iter().zip(&want.choices) {
            assert_eq!((r["at"].as_str(), r["choice"].as_str()), (Some(w.at.as_str()), Some(w.choice.as_str())));
            *choices.entry(w.at.clone()).or_default().entry(w.choice.clone()).or_default() += 1;
        }
        // The slots are the crop's: its main category, and the names present in id order.
        let main = format!("a {} close-up", slots.main);
        assert!(prompt.starts_with(&main) || prompt.starts_with(&format!("some {}", slots.present)), "{prompt}");
        assert!(!slots.main.is_empty(), "every orchard crop holds an instance");
        templated.push(image.clone());
    }
    assert_eq!(templated.len(), 4, "orchard-b and orchard-c, two crops each");
    assert_eq!(choices["prompt:1"].values().sum::<u64>(), 4);

    // The PNG records the expanded prompt as `vkdiff gen` writes it, and no template.
    let first = &templated[0];
    let text: BTreeMap<String, String> =
        png_text(&set.join(first["file_name"].as_str().unwrap())).into_iter().collect();
    assert_eq!(text["positive_prompt"], first["prompt"].as_str().unwrap());
    assert!(!text.contains_key("prompt_template"));

    // Stats count the images per expanded prompt and each choice per position.
    let stats: Value = serde_json::from_str(&run_ok(&["dataset", "stats", set_s, "--json"])).unwrap();
    assert_eq!(stats["prompts"], serde_json::to_value(&prompts).unwrap());
    assert_eq!(stats["prompt_templates"][TEMPLATE], 4);
    assert_eq!(stats["prompt_choices"][TEMPLATE], serde_json::to_value(&choices).unwrap());
    let summary = run_ok(&["dataset", "stats", set_s]);
    assert!(summary.contains(&format!("choices of template {TEMPLATE:?} (4 images):")), "{summary}");
    assert!(summary.contains("  __soil__: "), "{summary}");

    // `vkdiff gen` with the image's expanded prompt and seed writes the same PNG.
    let out = root.join("gen.png");
    let seed = first["seed"].to_string();
    let gen = ["gen", "--model", model_s, "--steps", "2", "--width", "64", "--height", "64", "--seed", &seed];
    run_ok(&[&gen[..], &["--prompt", first["prompt"].as_str().unwrap(), "--out", out.to_str().unwrap()]].concat());
    let want = std::fs::read(set.join(first["file_name"].as_str().unwrap())).unwrap();
    assert!(std::fs::read(&out).unwrap() == want, "gen did not reproduce {}", first["file_name"]);

    // `vkdiff gen` with a template: the expansion from its seed, and the template beside it.
    let out = root.join("gen-template.png");
    let gen_template = "{wet|dry} compost under __light/kind__";
    run_ok(&[&gen[..], &["--prompt", gen_template, "--wildcards", dir_s, "--out", out.to_str().unwrap()]].concat());
    let t = PromptTemplate::parse(gen_template).unwrap();
    let expanded = t.expand(seed.parse().unwrap(), &Wildcards::load(Some(&dir), &[&t]).unwrap(), None).unwrap();
    let text: BTreeMap<String, String> = png_text(&out).into_iter().collect();
    assert_eq!((text["positive_prompt"].as_str(), text["prompt_template"].as_str()), (&*expanded.prompt, gen_template));
    assert!(text["parameters"].starts_with(&expanded.prompt));

    // A resume with a changed wildcard file is refused, naming the flag; nothing changes.
    let before = std::fs::read(set.join("dataset.json")).unwrap();
    std::fs::write(dir.join("light/kind.txt"), "soft light\nhard light\nno light\n").unwrap();
    let e = refused(&strs(&dataset_args(set_s, dir_s, model_s)));
    assert!(e.contains("the content of the --wildcards files was"), "{e}");
    assert!(std::fs::read(set.join("dataset.json")).unwrap() == before);
}

#[test]
fn template_refusals_are_one_line_exit_2_and_write_nothing() {
    let root = scratch("prompt-template-refusals");
    let dir = wildcards(&root);
    std::fs::write(dir.join("empty.txt"), "# nothing here\n\n").unwrap();
    let model = fixture("pipeline/tiny-sdxl");
    let (dir_s, model_s) = (dir.to_str().unwrap(), model.to_str().unwrap());
    let out = root.join("out.png");
    let gen = |prompt: &str| {
        let args =
            ["gen", "--model", model_s, "--prompt", prompt, "--wildcards", dir_s, "--out", out.to_str().unwrap()];
        let e = refused(&args);
        assert!(!out.exists());
        e
    };
    let e = gen("a {wet|dry compost");
    assert!(e.contains("--prompt \"a {wet|dry compost\": `{` is not closed") && e.ends_with("at character 3"), "{e}");
    let e = gen("{x::wet|dry}");
    assert!(e.contains("weight `x` is not a non-negative number at character 2"), "{e}");
    let e = gen("on __missing__");
    assert!(e.contains("--wildcards") && e.contains("missing.txt: no such file, for __missing__"), "{e}");
    let e = gen("on __empty__");
    assert!(e.contains("empty.txt: holds no choice"), "{e}");
    let e = gen("a {category} close-up");
    assert!(e.contains("vkdiff gen has no scene"), "{e}");

    let set = root.join("set");
    let set_s = set.to_str().unwrap();
    let mut args = dataset_args(set_s, dir_s, model_s);
    let prompt = args.iter().position(|a| a == TEMPLATE).unwrap();
    for (template, why) in [("{a|b} ____", "`____` names no wildcard"), ("on __missing__", "missing.txt: no such file")]
    {
        args[prompt] = template.to_string();
        let e = refused(&strs(&args));
        assert!(e.contains(why), "{e}");
        assert!(!set.exists(), "nothing written");
    }
}
