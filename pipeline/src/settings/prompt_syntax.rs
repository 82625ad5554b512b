//! How `--prompt` text is read: literal, or A1111's emphasis syntax (`(word)` ×1.1, `[word]` ÷1.1,
//! `(word:1.3)` ×1.3, nested ones multiplied, `\(` for a literal bracket, `BREAK`) parsed into
//! runs of text and their weights.

use crate::error::{Error, Result};
use regex::Regex;
use vkdiff_setting::Message;

/// How `--prompt` text is read.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PromptSyntax {
    /// Literal text, cut at CLIP's 75 tokens as diffusers does.
    #[default]
    Plain,
    /// A1111 emphasis and prompts of any length.
    Weighted,
}

impl PromptSyntax {
    /// A prompt this syntax cannot read is refused before anything loads.
    pub fn check(self, prompt: &str) -> Result<()> {
        match self {
            PromptSyntax::Plain => Ok(()),
            PromptSyntax::Weighted => parse_attention(prompt).map(drop),
        }
    }
}

/// A1111's `parse_prompt_attention`: the text as runs of equal weight.
pub fn parse_attention(text: &str) -> Result<Vec<(String, f64)>> {
    let pattern = Regex::new(r"\\\(|\\\)|\\\[|\\]|\\\\|\\|\(|\[|:([+-]?[.\d]+)\)|\)|]|[^\\()\[\]:]+|:")
        .expect("attention pattern");
    let word_break = Regex::new(r"\bBREAK\b").expect("BREAK pattern");
    let mut runs: Vec<(String, f64)> = Vec::new();
    let (mut round, mut square) = (Vec::new(), Vec::new());
    let scale = |runs: &mut Vec<(String, f64)>, from: usize, by: f64| runs[from..].iter_mut().for_each(|r| r.1 *= by);
    for m in pattern.captures_iter(text) {
        let piece = &m[0];
        match (piece, m.get(1)) {
            (p, _) if p.starts_with('\\') => runs.push((p[1..].to_string(), 1.0)),
            ("(", _) => round.push(runs.len()),
            ("[", _) => square.push(runs.len()),
            (_, Some(w)) if !round.is_empty() => {
                let w: f64 = w.as_str().parse().map_err(|_| {
                    Error::Config(format!("prompt: weight `{}` in `{piece}` is not a number", w.as_str()))
                })?;
                let from = round.pop().expect("checked");
                scale(&mut runs, from, w);
            }
            (")", _) if !round.is_empty() => {
                let from = round.pop().expect("checked");
                scale(&mut runs, from, 1.1);
            }
            ("]", _) if !square.is_empty() => {
                let from = square.pop().expect("checked");
                scale(&mut runs, from, 1.0 / 1.1);
            }
            (p, _) => {
                if word_break.is_match(p) {
                    return Err(Error::Setting(
                        Message::setting("prompt")
                            .then(": BREAK is not supported by ")
                            .and("prompt_syntax")
                            .then(" weighted (diffusers' pipeline reads it as a word)"),
                    ));
                }
                runs.push((p.to_string(), 1.0));
            }
        }
    }
    for from in round {
        scale(&mut runs, from, 1.1);
    }
    for from in square {
        scale(&mut runs, from, 1.0 / 1.1);
    }
    if runs.is_empty() {
        runs.push((String::new(), 1.0));
    }
    let mut merged: Vec<(String, f64)> = Vec::with_capacity(runs.len());
    for (text, weight) in runs {
        match merged.last_mut() {
            Some(last) if last.1 == weight => last.0.push_str(&text),
            _ => merged.push((text, weight)),
        }
    }
    Ok(merged)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn runs(text: &str) -> Vec<(String, f64)> {
        parse_attention(text).unwrap()
    }

    #[test]
    fn a1111_examples() {
        // The examples of A1111's parse_prompt_attention docstring.
        assert_eq!(runs("normal text"), vec![("normal text".into(), 1.0)]);
        assert_eq!(
            runs("an (important) word"),
            vec![("an ".into(), 1.0), ("important".into(), 1.1), (" word".into(), 1.0)]
        );
        assert_eq!(runs("(unbalanced"), vec![("unbalanced".into(), 1.1)]);
        assert_eq!(runs(r"\(literal\]"), vec![("(literal]".into(), 1.0)]);
        assert_eq!(runs("(unnecessary)(parens)"), vec![("unnecessaryparens".into(), 1.1)]);
        let got = runs("a (((house:1.3)) [on] a (hill:0.5), sun, (((sky))).");
        let want = [
            ("a ", 1.0),
            ("house", 1.3 * 1.1 * 1.1),
            (" ", 1.1),
            ("on", 1.1 / 1.1),
            (" a ", 1.1),
            ("hill", 0.5 * 1.1),
            (", sun, ", 1.1),
            ("sky", 1.1 * 1.1 * 1.1 * 1.1),
            (".", 1.1),
        ];
        assert_eq!(got.len(), want.len(), "{got:?}");
        for ((t, w), (wt, ww)) in got.iter().zip(want) {
            assert_eq!(t, wt);
            assert!((w - ww).abs() < 1e-12, "{t}: {w} vs {ww}");
        }
        assert!(parse_attention("a (cat:1.2.3) dog").is_err());
        assert!(parse_attention("mushrooms BREAK soil").is_err());
        assert_eq!(runs(""), vec![(String::new(), 1.0)]);
    }
}
