//! CLIP's byte-level BPE tokenizer, token for token as transformers' `CLIPTokenizer` (tokenizers
//! backend) encodes a prompt for SDXL: padded and truncated to 77 ids.
//!
//! The steps, in transformers' order: special tokens are cut out of the raw text; each remaining
//! segment is NFC-normalised and lower-cased char by char; split into words by CLIP's pattern;
//! each word's UTF-8 bytes are mapped to GPT-2's byte symbols, `</w>` is appended to the last,
//! and BPE merges the pair of lowest rank, leftmost first, until none applies.

use crate::{Error, Result};
use regex::Regex;
use std::collections::HashMap;
use std::path::Path;
use unicode_normalization::UnicodeNormalization;
use vkdiff_formats::Error as FileError;

const BOS: &str = "<|startoftext|>";
const EOS: &str = "<|endoftext|>";
/// Token positions of every encoded prompt.
pub const CONTEXT: usize = 77;
const END_OF_WORD: &str = "</w>";

/// CLIP's word pattern. The special-token literals only matter when typed in another case, since
/// exact ones are cut out before; lower-casing turns e.g. `<|EndOfText|>` into one such word.
const WORDS: &str = r"<\|startoftext\|>|<\|endoftext\|>|'s|'t|'re|'ve|'m|'ll|'d|\p{L}+|\p{N}|[^\s\p{L}\p{N}]+";
/// transformers' byte-level step splits each word again by GPT-2's pattern; that changes only the
/// special-token words above (`<|`, `endoftext`, `|>`). Words hold no whitespace, so GPT-2's
/// whitespace alternatives are left out.
const BYTE_LEVEL_WORDS: &str = r"'s|'t|'re|'ve|'m|'ll|'d|\p{L}+|\p{N}+|[^\s\p{L}\p{N}]+";

/// The merges open_clip uses (`bpe_simple_vocab_16e6.txt.gz` lines 1..=48894), in merges.txt form.
const BUILTIN_MERGES: &str = include_str!("../assets/clip_merges.txt");

pub struct ClipTokenizer {
    /// Vocabulary ids of each byte's symbol, without and with `</w>`.
    byte_ids: [[u32; 256]; 2],
    /// (left, right) → (rank, merged id).
    merges: HashMap<(u32, u32), (u32, u32)>,
    /// Tokens cut out of the raw text before normalisation: (text, id).
    specials: Vec<(String, u32)>,
    words: Regex,
    byte_level_words: Regex,
    bos_id: u32,
    eos_id: u32,
    pad_id: u32,
}

impl ClipTokenizer {
    /// An SDXL tokenizer folder (`tokenizer/` or `tokenizer_2/`): vocab.json + merges.txt, and the
    /// pad token from special_tokens_map.json or tokenizer_config.json (the former wins, as in
    /// transformers); default pad `<|endoftext|>`.
    pub fn from_dir(dir: &Path) -> Result<ClipTokenizer> {
        let vocab_path = dir.join("vocab.json");
        let vocab: HashMap<String, u32> =
            serde_json::from_str(&read(&vocab_path)?).map_err(|e| format_error(&vocab_path, e))?;
        let mut pad = None;
        for name in ["special_tokens_map.json", "tokenizer_config.json"] {
            let path = dir.join(name);
            if pad.is_none() && path.exists() {
                pad = pad_token(&path)?;
            }
        }
        let merges_path = dir.join("merges.txt");
        let merges = read(&merges_path)?;
        Self::new(vocab, &merges, pad.as_deref().unwrap_or(EOS), &merges_path, &vocab_path)
    }

    /// The built-in CLIP vocabulary (single-file checkpoints carry no tokenizer), padding with
    /// `pad_token`: `<|endoftext|>` for CLIP-L (id 49407), `!` for OpenCLIP bigG (id 0).
    pub fn builtin(pad_token: &str) -> Result<ClipTokenizer> {
        let vocab = builtin_vocab().into_iter().zip(0..).collect();
        let origin = Path::new("built-in CLIP vocabulary");
        Self::new(vocab, BUILTIN_MERGES, pad_token, origin, origin)
    }

    /// The built-in vocabulary as files transformers' `CLIPTokenizer` reads: `dir/vocab.json` and
    /// `dir/merges.txt` (for references that must tokenize as vkdiff does).
    pub fn write_builtin(dir: &Path) -> Result<()> {
        let io = |source| Error::from(FileError::Io { path: dir.to_path_buf(), source });
        std::fs::create_dir_all(dir).map_err(io)?;
        let vocab: serde_json::Map<String, serde_json::Value> =
            builtin_vocab().into_iter().zip(0u32..).map(|(token, id)| (token, id.into())).collect();
        std::fs::write(dir.join("vocab.json"), serde_json::Value::Object(vocab).to_string()).map_err(io)?;
        std::fs::write(dir.join("merges.txt"), BUILTIN_MERGES).map_err(io)
    }

    fn new(
        vocab: HashMap<String, u32>,
        merges_text: &str,
        pad: &str,
        merges_path: &Path,
        vocab_path: &Path,
    ) -> Result<ClipTokenizer> {
        let id = |token: &str| {
            vocab.get(token).copied().ok_or_else(|| FileError::Format {
                path: vocab_path.to_path_buf(),
                why: format!("token {token:?} is not in the vocabulary"),
            })
        };
        let (bos_id, eos_id, pad_id) = (id(BOS)?, id(EOS)?, id(pad)?);
        // A byte symbol missing from the vocabulary becomes the unknown token, which CLIP
        // declares to be EOS.
        let mut byte_ids = [[eos_id; 256]; 2];
        for (byte, c) in byte_symbols() {
            let symbol = c.to_string();
            byte_ids[0][byte as usize] = vocab.get(&symbol).copied().unwrap_or(eos_id);
            byte_ids[1][byte as usize] = vocab.get(&format!("{symbol}{END_OF_WORD}")).copied().unwrap_or(eos_id);
        }
        let mut merges = HashMap::new();
        for (rank, (line_no, line)) in (0..).zip(merge_lines(merges_text)) {
            let bad = |why: String| FileError::Format {
                path: merges_path.to_path_buf(),
                why: format!("line {line_no}: {why}"),
            };
            let (a, b) = line
                .split_once(' ')
                .filter(|(_, b)| !b.contains(' '))
                .ok_or_else(|| bad(format!("expected two symbols, found {line:?}")))?;
            let known = |token: &str| {
                vocab.get(token).copied().ok_or_else(|| bad(format!("{token:?} is not in the vocabulary")))
            };
            merges.insert((known(a)?, known(b)?), (rank, known(&format!("{a}{b}"))?));
        }
        let mut specials = vec![(BOS.to_string(), bos_id), (EOS.to_string(), eos_id)];
        if pad != BOS && pad != EOS {
            specials.push((pad.to_string(), pad_id));
        }
        Ok(ClipTokenizer {
            byte_ids,
            merges,
            specials,
            words: Regex::new(WORDS).expect("CLIP word pattern"),
            byte_level_words: Regex::new(BYTE_LEVEL_WORDS).expect("byte-level word pattern"),
            bos_id,
            eos_id,
            pad_id,
        })
    }

    /// 77 ids: BOS, the prompt's first 75 tokens, EOS, then the pad id.
    pub fn encode(&self, text: &str) -> Vec<u32> {
        let mut ids = vec![self.bos_id];
        ids.extend(self.tokens(text));
        ids.truncate(CONTEXT - 1);
        ids.push(self.eos_id);
        ids.resize(CONTEXT, self.pad_id);
        ids
    }

    /// Every token of `text`, without BOS, EOS or a length limit.
    pub fn tokens(&self, text: &str) -> Vec<u32> {
        let mut ids = Vec::new();
        let mut rest = text;
        while let Some((at, len, id)) = self.next_special(rest) {
            self.encode_plain(&rest[..at], &mut ids);
            ids.push(id);
            rest = &rest[at + len..];
        }
        self.encode_plain(rest, &mut ids);
        ids
    }

    pub fn pad_id(&self) -> u32 {
        self.pad_id
    }

    pub fn bos_id(&self) -> u32 {
        self.bos_id
    }

    pub fn eos_id(&self) -> u32 {
        self.eos_id
    }

    /// The leftmost special token in the raw text, the longest there: (byte offset, length, id).
    fn next_special(&self, text: &str) -> Option<(usize, usize, u32)> {
        text.char_indices().find_map(|(at, _)| {
            let here = self.specials.iter().filter(|(s, _)| text[at..].starts_with(s.as_str()));
            here.max_by_key(|(s, _)| s.len()).map(|(s, id)| (at, s.len(), *id))
        })
    }

    /// Appends the tokens of text holding no special token. transformers also collapses
    /// whitespace runs to one space here; the word split drops whitespace anyway.
    fn encode_plain(&self, text: &str, ids: &mut Vec<u32>) {
        // Char by char as tokenizers does: no final-sigma rule, `Σ` is always `σ`.
        let normal: String = text.nfc().flat_map(char::to_lowercase).collect();
        for word in self.words.find_iter(&normal) {
            for word in self.byte_level_words.find_iter(word.as_str()) {
                self.bpe(word.as_str().as_bytes(), ids);
            }
        }
    }

    fn bpe(&self, word: &[u8], ids: &mut Vec<u32>) {
        let last = word.len() - 1;
        let mut symbols: Vec<u32> =
            word.iter().enumerate().map(|(i, &b)| self.byte_ids[usize::from(i == last)][b as usize]).collect();
        loop {
            let best = (0..symbols.len().saturating_sub(1))
                .filter_map(|i| self.merges.get(&(symbols[i], symbols[i + 1])).map(|&(rank, id)| (rank, i, id)))
                .min();
            let Some((_, i, id)) = best else { break };
            symbols[i] = id;
            symbols.remove(i + 1);
        }
        ids.extend(symbols);
    }
}

/// GPT-2's reversible byte → char map, in open_clip's vocabulary order: the printable Latin-1
/// bytes stand for themselves, the others take chars from U+0100 on, in byte order.
fn byte_symbols() -> Vec<(u8, char)> {
    let printable = |b: u8| matches!(b, b'!'..=b'~' | 0xA1..=0xAC | 0xAE..=0xFF);
    let mut symbols: Vec<(u8, char)> = (0..=255u8).filter(|&b| printable(b)).map(|b| (b, char::from(b))).collect();
    let others = (0..=255u8).filter(|&b| !printable(b));
    symbols.extend(others.zip(256u32..).map(|(b, c)| (b, char::from_u32(c).expect("U+0100 and up"))));
    symbols
}

/// merges.txt's merge lines with their 1-based line numbers: the `#version` header is skipped,
/// as tokenizers does.
fn merge_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    (1..).zip(text.lines()).filter(|(_, line)| !line.starts_with("#version"))
}

/// `pad_token` of a token config, given as a string or as an object with `content`.
fn pad_token(path: &Path) -> Result<Option<String>> {
    let json: serde_json::Value = serde_json::from_str(&read(path)?).map_err(|e| format_error(path, e))?;
    let pad = match json.get("pad_token") {
        None | Some(serde_json::Value::Null) => return Ok(None),
        Some(pad) => pad.as_str().or_else(|| pad.get("content").and_then(|c| c.as_str())),
    };
    Ok(pad.map(|p| Some(p.to_string())).ok_or_else(|| FileError::Format {
        path: path.to_path_buf(),
        why: "pad_token is neither a string nor an object with a string \"content\"".into(),
    })?)
}

fn read(path: &Path) -> Result<String> {
    Ok(std::fs::read_to_string(path).map_err(|source| FileError::Io { path: path.to_path_buf(), source })?)
}

fn format_error(path: &Path, e: serde_json::Error) -> Error {
    FileError::Format { path: path.to_path_buf(), why: e.to_string() }.into()
}

/// open_clip's vocabulary in id order: byte symbols, the same with `</w>`, each merge joined, the
/// specials.
fn builtin_vocab() -> Vec<String> {
    let symbols: Vec<String> = byte_symbols().into_iter().map(|(_, c)| c.to_string()).collect();
    let mut vocab = symbols.clone();
    vocab.extend(symbols.iter().map(|s| format!("{s}{END_OF_WORD}")));
    vocab.extend(
        merge_lines(BUILTIN_MERGES).filter_map(|(_, line)| line.split_once(' ').map(|(a, b)| format!("{a}{b}"))),
    );
    vocab.extend([BOS.to_string(), EOS.to_string()]);
    vocab
}
