//! The CLIP tokenizer held to transformers' CLIPTokenizer on the corpus written by
//! tools/make_tokenizer_fixtures.py.

use std::collections::HashMap;
use std::path::PathBuf;
use vkdiff_pipeline::ClipTokenizer;

struct Case {
    text: String,
    /// transformers' ids per tokenizer folder name.
    ids: HashMap<String, Vec<u32>>,
}

struct Corpus {
    /// (tokenizer folder name, its pad token).
    pads: Vec<(String, String)>,
    cases: Vec<Case>,
}

fn corpus() -> Corpus {
    let path = vkdiff_testkit::fixture("pipeline").join("tokenizer_corpus.json");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
    let pads = json["pad_tokens"].as_object().unwrap();
    let pads: Vec<(String, String)> = pads.iter().map(|(k, v)| (k.clone(), v.as_str().unwrap().into())).collect();
    let cases: Vec<Case> = serde_json::from_value::<Vec<serde_json::Value>>(json["cases"].clone())
        .unwrap()
        .into_iter()
        .map(|case| Case {
            text: case["text"].as_str().unwrap().into(),
            ids: pads
                .iter()
                .map(|(name, _)| (name.clone(), serde_json::from_value(case[name.as_str()].clone()).unwrap()))
                .collect(),
        })
        .collect();
    assert!(cases.len() >= 250, "corpus has only {} prompts", cases.len());
    Corpus { pads, cases }
}

/// Every case's ids for tokenizer folder `folder` from `tokenizer`; mismatches listed prompt by prompt.
fn check(corpus: &Corpus, tokenizer: &ClipTokenizer, folder: &str, what: &str) {
    let mut failures = Vec::new();
    for case in &corpus.cases {
        let want = &case.ids[folder];
        let got = tokenizer.encode(&case.text);
        if &got != want {
            let first = got.iter().zip(want).position(|(g, w)| g != w).unwrap_or(0);
            failures.push(format!(
                "{:?}\n    first difference at {first}\n    got  {:?}\n    want {:?}",
                case.text,
                &got[first..(first + 8).min(got.len())],
                &want[first..(first + 8).min(want.len())]
            ));
        }
    }
    assert!(
        failures.is_empty(),
        "{what}: {} of {} prompts differ from transformers:\n{}",
        failures.len(),
        corpus.cases.len(),
        failures.join("\n")
    );
}

fn folder(name: &str) -> PathBuf {
    vkdiff_testkit::fixture("pipeline").join("clip-tokenizer").join(name)
}

#[test]
fn from_dir_matches_transformers() {
    let corpus = corpus();
    for (name, pad) in &corpus.pads {
        let tokenizer = ClipTokenizer::from_dir(&folder(name)).unwrap();
        assert_eq!(tokenizer.pad_id(), if pad == "!" { 0 } else { 49407 }, "{name}");
        check(&corpus, &tokenizer, name, &format!("from_dir({name})"));
    }
}

#[test]
fn builtin_matches_transformers() {
    let corpus = corpus();
    for (name, pad) in &corpus.pads {
        let tokenizer = ClipTokenizer::builtin(pad).unwrap();
        check(&corpus, &tokenizer, name, &format!("builtin({pad:?})"));
    }
}

/// A scratch folder holding `files` copied from the CLIP-L fixture folder.
fn scratch(test: &str, files: &[&str]) -> PathBuf {
    let dir = vkdiff_testkit::scratch(test);
    for file in files {
        std::fs::copy(folder("tokenizer").join(file), dir.join(file)).unwrap();
    }
    dir
}

#[test]
fn missing_vocab_names_the_file() {
    let dir = scratch("missing-vocab", &["merges.txt"]);
    let error = ClipTokenizer::from_dir(&dir).err().expect("a folder without vocab.json loads").to_string();
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(error.contains(&dir.join("vocab.json").display().to_string()), "{error}");
    assert!(!error.contains('\n'), "{error}");
}

#[test]
fn pad_token_forms() {
    let dir = scratch("pad-forms", &["vocab.json", "merges.txt"]);
    let without_config = ClipTokenizer::from_dir(&dir).unwrap().pad_id();
    // The object form, as in some SDXL uploads' special_tokens_map.json.
    let map = r#"{"pad_token": {"content": "!", "lstrip": false, "normalized": false}}"#;
    std::fs::write(dir.join("special_tokens_map.json"), map).unwrap();
    let from_object = ClipTokenizer::from_dir(&dir).unwrap().pad_id();
    std::fs::remove_dir_all(&dir).unwrap();
    assert_eq!((without_config, from_object), (49407, 0));
}

#[test]
fn the_builtin_vocabulary_is_written_as_transformers_files() {
    // What `vkdiff bench gen` hands diffusers' tokenizers: the files transformers saved.
    let dir = vkdiff_testkit::scratch("builtin-tokenizer");
    ClipTokenizer::write_builtin(&dir).unwrap();
    let saved = vkdiff_testkit::fixture("pipeline/clip-tokenizer/tokenizer");
    let vocab =
        |path: PathBuf| -> serde_json::Value { serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap() };
    assert_eq!(vocab(dir.join("vocab.json")), vocab(saved.join("vocab.json")));
    assert_eq!(std::fs::read(dir.join("merges.txt")).unwrap(), std::fs::read(saved.join("merges.txt")).unwrap());
}
