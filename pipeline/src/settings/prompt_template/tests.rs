use super::*;
use crate::settings::parse_attention;
use std::collections::BTreeMap;
use std::path::PathBuf;
use vkdiff_render::coco::Category;

fn template(text: &str) -> PromptTemplate {
    PromptTemplate::parse(text).unwrap_or_else(|e| panic!("{text}: {e}"))
}

/// The expansion of a template without wildcards or slots.
fn expand(text: &str, seed: u64) -> Expansion {
    let t = template(text);
    t.expand(seed, &Wildcards::load(None, &[&t]).unwrap(), None).unwrap()
}

/// The error of a template that does not parse.
fn refusal(text: &str) -> String {
    PromptTemplate::parse(text).map(|t| panic!("{text} parsed: {t:?}")).unwrap_err().to_string()
}

/// A folder of wildcard files: (name, content).
fn folder(name: &str, files: &[(&str, &str)]) -> PathBuf {
    let dir = vkdiff_testkit::scratch(&format!("prompt-template-{name}"));
    for (file, text) in files {
        let path = dir.join(file);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, text).unwrap();
    }
    dir
}

/// Every expansion of `text` over `seeds`, counted.
fn tally(text: &str, wildcards: Option<&std::path::Path>, seeds: u64) -> BTreeMap<String, u64> {
    let t = template(text);
    let w = Wildcards::load(wildcards, &[&t]).unwrap();
    let mut counts = BTreeMap::new();
    for seed in 0..seeds {
        *counts.entry(t.expand(seed, &w, None).unwrap().prompt).or_default() += 1;
    }
    counts
}

#[test]
fn plain_prompts_are_their_own_expansion() {
    for text in [
        "white button mushrooms on dark compost",
        "",
        "a (house:1.3) [on] a hill, \\(literal\\) \\\\ back",
        "snake__case and a lone __ and 3::2 and a|b and $$",
    ] {
        let t = template(text);
        assert!(!t.is_template(), "{text}");
        for seed in [0, 1, u64::MAX] {
            assert_eq!(expand(text, seed), Expansion { prompt: text.to_string(), choices: vec![] });
        }
    }
}

#[test]
fn choices_weights_nesting_and_empty_choices() {
    let all = tally("{wet|dry|freshly watered} compost", None, 300);
    assert_eq!(all.keys().collect::<Vec<_>>(), ["dry compost", "freshly watered compost", "wet compost"]);
    let weighted = tally("{0::never|2.5::often|.5::rarely}", None, 400);
    assert!(!weighted.contains_key("never") && weighted["often"] > weighted["rarely"], "{weighted:?}");
    assert_eq!(tally("{|very }wet", None, 100).keys().collect::<Vec<_>>(), ["very wet", "wet"]);
    assert_eq!(tally("{|}", None, 10).keys().collect::<Vec<_>>(), [""]);
    assert_eq!(tally("{ 3 :: x }", None, 10).keys().collect::<Vec<_>>(), [" x "], "weights are trimmed, text not");
    for seed in 0..100 {
        let e = expand("{a {b|c}|d} e", seed);
        match e.prompt.as_str() {
            "d e" => assert_eq!(e.choices, [Chosen { at: "prompt:1".into(), choice: "d".into() }]),
            p @ ("a b e" | "a c e") => assert_eq!(
                e.choices,
                [
                    Chosen { at: "prompt:1".into(), choice: "a {b|c}".into() },
                    Chosen { at: "prompt:4".into(), choice: p[2..3].into() }
                ],
                "the outer choice first, then the one inside what it took"
            ),
            other => panic!("{other}"),
        }
    }
    assert_eq!(tally("{a {b|c}|d}", None, 300).len(), 3);
}

#[test]
fn escapes_are_literal_and_other_backslashes_stay_for_the_prompt_syntax() {
    let e = expand(r"\{a\|b\} {x\|y|z}", 3);
    assert!(e.prompt == "{a|b} x|y" || e.prompt == "{a|b} z", "{}", e.prompt);
    assert!(template(r"\{a\}").is_template(), "an escape changes the text");
    assert_eq!(expand(r"\(x\) \\{a}", 0).prompt, r"\(x\) \\a");
}

#[test]
fn expansions_are_read_by_the_weighted_syntax_after() {
    for seed in 0..20 {
        let e = expand("{(wet:1.2)|[dry]} (soil:0.8)", seed);
        let runs = parse_attention(&e.prompt).unwrap();
        let wet = e.prompt.starts_with("(wet");
        let first = if wet { ("wet".to_string(), 1.2) } else { ("dry".to_string(), 1.0 / 1.1) };
        assert_eq!(runs[0], first, "{}", e.prompt);
        assert_eq!(runs.last().unwrap(), &("soil".to_string(), 0.8));
    }
}

#[test]
fn the_same_seed_gives_the_same_expansion() {
    let text = "{a|b|c} {d|{e|f}} {2::g|h|i|j}";
    let runs: Vec<Vec<Expansion>> = (0..2).map(|_| (0..50).map(|s| expand(text, s)).collect()).collect();
    assert_eq!(runs[0], runs[1]);
    let distinct: std::collections::BTreeSet<&String> = runs[0].iter().map(|e| &e.prompt).collect();
    assert!(distinct.len() > 10, "seeds give other expansions: {distinct:?}");
}

#[test]
fn wildcards_read_lines_of_files_recursively() {
    let dir = folder(
        "read",
        &[
            ("soil.txt", "# soils\n\n  dark compost  \n__plants/fruit__ bed\n"),
            ("plants/fruit.txt", "{ripe|green} apple\n"),
        ],
    );
    let t = template("on __soil__");
    let w = Wildcards::load(Some(&dir), &[&t]).unwrap();
    let mut seen = BTreeMap::new();
    for seed in 0..200 {
        let e = t.expand(seed, &w, None).unwrap();
        if e.prompt == "on dark compost" {
            assert_eq!(e.choices, [Chosen { at: "__soil__".into(), choice: "dark compost".into() }]);
        } else {
            assert_eq!(e.choices.len(), 3, "{e:?}");
            assert_eq!(e.choices[1].at, "__plants/fruit__");
            assert_eq!(e.choices[2].at, "plants/fruit.txt:1:1");
            assert_eq!(e.prompt, format!("on {} apple bed", e.choices[2].choice));
        }
        *seen.entry(e.prompt).or_insert(0) += 1;
    }
    assert_eq!(seen.keys().collect::<Vec<_>>(), ["on dark compost", "on green apple bed", "on ripe apple bed"]);
    let changed =
        folder("read-changed", &[("soil.txt", "dark compost\n"), ("plants/fruit.txt", "{ripe|green} apple\n")]);
    let other = Wildcards::load(Some(&changed), &[&t]).unwrap();
    assert_ne!(w.digest(), other.digest(), "the digest follows the files' content");
    assert_eq!(w.digest(), Wildcards::load(Some(&dir), &[&t]).unwrap().digest());
}

#[test]
fn wildcard_refusals_name_the_file_or_the_cycle() {
    let dir = folder(
        "refusals",
        &[("empty.txt", "# nothing\n\n"), ("a.txt", "x __b__\n"), ("b.txt", "{y|__a__}\n"), ("bad.txt", "ok\n{oops\n")],
    );
    let load = |text: &str, dir: Option<&std::path::Path>| {
        let t = template(text);
        Wildcards::load(dir, &[&t]).map(|_| ()).unwrap_err().to_string()
    };
    let e = load("__soil__", Some(&dir));
    assert!(e.contains("soil.txt: no such file, for __soil__"), "{e}");
    let e = load("__empty__", Some(&dir));
    assert!(e.contains("empty.txt: holds no choice"), "{e}");
    let e = load("__a__", Some(&dir));
    assert!(e.contains("__a__ → __b__ → __a__ is a cycle"), "{e}");
    let e = load("__bad__", Some(&dir));
    assert!(e.contains("bad.txt line 2: `{` is not closed") && e.contains("at character 1"), "{e}");
    let e = load("x __soil__", None);
    assert!(e.contains("__soil__ needs wildcards DIR"), "{e}");
    assert!(!e.contains('\n'));
}

#[test]
fn refusals_name_the_template_and_the_position() {
    for (text, why, at) in [
        ("a {b|c", "`{` is not closed", 3),
        ("a}b", "`}` closes no `{`", 2),
        ("{x::a|b}", "weight `x` is not a non-negative number", 2),
        ("{a|-1::b}", "weight `-1` is not a non-negative number", 4),
        ("{1.2.3::a}", "weight `1.2.3`", 2),
        ("x {}", "`{}` has no choices", 3),
        ("{0::a|0::b}", "every choice weighs 0", 1),
        ("a ____ b", "`____` names no wildcard", 3),
        ("{2$$a|b}", "not supported", 2),
        ("__../x__", "inside the wildcards folder", 1),
    ] {
        let e = refusal(text);
        assert!(e.starts_with(&format!("prompt \"{text}\": ")), "{e}");
        assert!(e.contains(why) && e.ends_with(&format!("at character {at}")), "{text}: {e}");
    }
    let deep = format!("{}x{}", "{".repeat(MAX_DEPTH + 1), "}".repeat(MAX_DEPTH + 1));
    assert!(refusal(&deep).contains("nest deeper"));
}

#[test]
fn category_slots_take_the_scene_and_are_refused_without_one() {
    let cats = |names: &[&str]| -> Vec<Category> {
        (names.iter().enumerate()).map(|(i, n)| Category::new(i as u32 + 1, n, "")).collect()
    };
    let categories = cats(&["apple", "leaf", "branch"]);
    let slots = CategorySlots::new([3, 2, 3, 2, 1], &categories);
    assert_eq!(
        slots,
        CategorySlots { main: "leaf".into(), present: "apple, leaf, branch".into() },
        "ties to the lowest id"
    );
    assert_eq!(CategorySlots::new([3, 3, 1], &categories).main, "branch");
    assert_eq!(CategorySlots::new([], &categories), CategorySlots::default());
    let t = template("{category} among {categories}");
    let w = Wildcards::load(None, &[&t]).unwrap();
    assert_eq!(t.expand(0, &w, Some(&slots)).unwrap().prompt, "leaf among apple, leaf, branch");
    assert!(w.uses_categories(&t));
    let e = w.check_no_scene(&t).unwrap_err().to_string();
    assert!(e.contains("vkdiff gen has no scene") && !e.contains('\n'), "{e}");
    assert!(t.expand(0, &w, None).is_err());
    let dir = folder("slots", &[("thing.txt", "a {category}\n")]);
    let t = template("__thing__");
    assert!(Wildcards::load(Some(&dir), &[&t]).unwrap().uses_categories(&t), "a slot in a wildcard's line counts");
}

/// P(χ²_k > x) for an even `k`: e^(−x/2) Σ_{i<k/2} (x/2)^i / i!.
fn chi2_survival(x: f64, k: usize) -> f64 {
    assert!(k.is_multiple_of(2) && k > 0);
    let mut term = 1.0;
    let mut sum = 0.0;
    for i in 0..k / 2 {
        if i > 0 {
            term *= x / 2.0 / i as f64;
        }
        sum += term;
    }
    (-x / 2.0).exp() * sum
}

/// The x with P(χ²_k > x) = p, by bisection.
fn chi2_critical(p: f64, k: usize) -> f64 {
    let (mut lo, mut hi) = (0.0, 1000.0);
    for _ in 0..200 {
        let mid = (lo + hi) / 2.0;
        if chi2_survival(mid, k) > p {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

/// Pearson's statistic of `counts` against `probabilities`, over 10,000 seeds, checked below
/// the 0.001 critical value of its degrees of freedom.
fn goodness_of_fit(what: &str, counts: &BTreeMap<String, u64>, probabilities: &[(&str, f64)]) -> f64 {
    const SEEDS: f64 = 10_000.0;
    assert_eq!(counts.values().sum::<u64>() as f64, SEEDS);
    assert_eq!(counts.len(), probabilities.len(), "{counts:?}");
    assert!((probabilities.iter().map(|p| p.1).sum::<f64>() - 1.0).abs() < 1e-12);
    let statistic: f64 = (probabilities.iter())
        .map(|&(outcome, p)| {
            let expected = p * SEEDS;
            let observed = counts.get(outcome).copied().unwrap_or(0) as f64;
            (observed - expected).powi(2) / expected
        })
        .sum();
    let df = probabilities.len() - 1;
    let critical = chi2_critical(0.001, df);
    eprintln!(
        "{what}: χ² = {statistic:.3} on {df} degrees of freedom, p = {:.3}; 0.001 critical value {critical:.3}; \
        counts {counts:?}",
        chi2_survival(statistic, df)
    );
    assert!(statistic < critical, "{what}: χ² {statistic} ≥ {critical}");
    statistic
}

#[test]
fn chi_square_critical_values_match_the_tables() {
    // NIST/SEMATECH e-Handbook of Statistical Methods, 1.3.6.7.4, upper-tail 0.001: 13.816 (2), 18.467 (4).
    assert!((chi2_critical(0.001, 2) - 13.816).abs() < 1e-3);
    assert!((chi2_critical(0.001, 4) - 18.467).abs() < 1e-3);
}

#[test]
fn choices_follow_their_weights_chi_square() {
    let counts = tally("{3::a|b|c}", None, 10_000);
    goodness_of_fit("{3::a|b|c}", &counts, &[("a", 3.0 / 5.0), ("b", 1.0 / 5.0), ("c", 1.0 / 5.0)]);
    let dir = folder("chi2", &[("w.txt", "# x, or z and u by 3 to 1\nx\n\n  {3::z|u}  \n")]);
    let counts = tally("{__w__|2::d {e|f}}", Some(&dir), 10_000);
    let (wildcard, group) = (1.0 / 3.0, 2.0 / 3.0);
    goodness_of_fit(
        "{__w__|2::d {e|f}} with w.txt = x, {3::z|u}",
        &counts,
        &[
            ("x", wildcard / 2.0),
            ("z", wildcard / 2.0 * 3.0 / 4.0),
            ("u", wildcard / 2.0 / 4.0),
            ("d e", group / 2.0),
            ("d f", group / 2.0),
        ],
    );
}
