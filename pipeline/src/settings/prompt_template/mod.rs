//! Prompts that vary per image, in sd-dynamic-prompts' syntax: choices `{wet|dry}`, weighted
//! choices `{3::wet|dry}` (a choice without a weight weighs 1), nested choices, wildcards
//! `__soil__` (a line of `soil.txt` in the wildcards folder), the scene's category slots
//! `{category}` and `{categories}`, and the escapes `\{`, `\}`, `\|`. A template is expanded from
//! a seed by its own generator ([`expand`]); the text that comes out is then read by the prompt
//! syntax (`--prompt-syntax`) as any prompt is. A prompt with none of this syntax is its own
//! expansion, byte for byte.

mod expand;
mod wildcards;

pub use expand::{splitmix64, CategorySlots, Chosen, Expansion};
pub use wildcards::Wildcards;

use crate::error::{Error, Result};
use vkdiff_setting::Message;

/// Nesting deeper than this (choices in choices, wildcards in wildcards) is refused.
pub const MAX_DEPTH: usize = 32;

/// One piece of a parsed template.
#[derive(Clone, Debug, PartialEq)]
enum Node {
    /// Literal text, escapes resolved.
    Text(String),
    /// `{…|…}`: one alternative drawn by weight; `at` names where the group is written.
    Group { at: String, alternatives: Vec<Alternative> },
    /// `__name__`: a line of the wildcard file `name.txt`.
    Wildcard(String),
    /// `{category}`: the image's main category.
    Category,
    /// `{categories}`: the categories present in the image, in id order.
    Categories,
}

#[derive(Clone, Debug, PartialEq)]
struct Alternative {
    weight: f64,
    /// As written, without its weight: what a record of the choice shows.
    written: String,
    nodes: Vec<Node>,
}

/// Where a template's text comes from, for errors and for naming a choice's position.
#[derive(Clone, Copy)]
enum Origin<'a> {
    /// A prompt: positions are `prompt:COLUMN`.
    Prompt,
    /// Line `line` of the wildcard file `file`: positions are `FILE:LINE:COLUMN`.
    Line { file: &'a str, line: usize },
}

/// A prompt parsed as a template.
#[derive(Clone, Debug, PartialEq)]
pub struct PromptTemplate {
    text: String,
    nodes: Vec<Node>,
}

impl PromptTemplate {
    /// Parses `text`; a template that cannot be read is one line naming it and the column
    /// (1-based, in characters) where it goes wrong.
    pub fn parse(text: &str) -> Result<PromptTemplate> {
        let nodes = parse_nodes(text, Origin::Prompt)?;
        Ok(PromptTemplate { text: text.to_string(), nodes })
    }

    /// The template as written.
    pub fn text(&self) -> &str {
        &self.text
    }

    /// Whether the text uses any template syntax; a prompt that does not is its own expansion.
    pub fn is_template(&self) -> bool {
        match &self.nodes[..] {
            [] => false,
            [Node::Text(t)] => *t != self.text,
            _ => true,
        }
    }

    /// The wildcards the template names itself (not those its wildcards' lines name).
    fn wildcards(&self) -> Vec<&str> {
        let mut names = Vec::new();
        walk(&self.nodes, &mut |n| {
            if let Node::Wildcard(name) = n {
                names.push(name.as_str());
            }
        });
        names
    }
}

/// Every node of `nodes`, alternatives included, in reading order.
fn walk<'a>(nodes: &'a [Node], visit: &mut dyn FnMut(&'a Node)) {
    for node in nodes {
        visit(node);
        if let Node::Group { alternatives, .. } = node {
            alternatives.iter().for_each(|a| walk(&a.nodes, visit));
        }
    }
}

/// Parses `text` (a prompt, or a line of a wildcard file).
fn parse_nodes(text: &str, origin: Origin) -> Result<Vec<Node>> {
    let mut parser = Parser { text, chars: text.chars().collect(), pos: 0, origin };
    let nodes = parser.sequence(0)?;
    match parser.peek() {
        None => Ok(nodes),
        Some(_) => Err(parser.error(parser.pos, "`}` closes no `{` (write `\\}` for the character)")),
    }
}

struct Parser<'a> {
    text: &'a str,
    chars: Vec<char>,
    pos: usize,
    origin: Origin<'a>,
}

/// The characters a wildcard's name may hold.
fn name_char(c: char) -> bool {
    c.is_alphanumeric() || "-_/.".contains(c)
}

impl Parser<'_> {
    fn peek(&self) -> Option<char> {
        self.chars.get(self.pos).copied()
    }

    fn column(&self, pos: usize) -> usize {
        pos + 1
    }

    /// Where `pos` is, as a choice's record names it.
    fn at(&self, pos: usize) -> String {
        match self.origin {
            Origin::Prompt => format!("prompt:{}", self.column(pos)),
            Origin::Line { file, line } => format!("{file}:{line}:{}", self.column(pos)),
        }
    }

    fn error(&self, pos: usize, why: &str) -> Error {
        let (what, text) = match self.origin {
            Origin::Prompt => (Message::setting("prompt"), format!(" \"{}\"", self.text)),
            Origin::Line { file, line } => (Message::setting("wildcards"), format!(" {file} line {line}")),
        };
        Error::Setting(what.then(format!("{text}: {why} at character {}", self.column(pos))))
    }

    /// Nodes up to the end, or (inside a group) up to its next `|` or `}`.
    fn sequence(&mut self, depth: usize) -> Result<Vec<Node>> {
        let mut nodes = Vec::new();
        let mut text = String::new();
        while let Some(c) = self.peek() {
            let start = self.pos;
            match c {
                '|' | '}' if depth > 0 => break,
                '}' => break,
                '\\' => {
                    let next = self.chars.get(self.pos + 1).copied();
                    match next {
                        Some(e @ ('{' | '}' | '|')) => text.push(e),
                        // Other escapes are the prompt syntax's (`\(`, `\\`): kept as written.
                        Some(e) => {
                            text.push('\\');
                            text.push(e);
                        }
                        None => text.push('\\'),
                    }
                    self.pos += next.map_or(1, |_| 2);
                    continue;
                }
                '{' => {
                    let node = self.brace(depth)?;
                    flush(&mut text, &mut nodes);
                    nodes.push(node);
                    continue;
                }
                '_' if self.chars.get(start + 1) == Some(&'_') => {
                    if let Some(name) = self.wildcard()? {
                        flush(&mut text, &mut nodes);
                        nodes.push(Node::Wildcard(name));
                        continue;
                    }
                    text.push_str("__");
                    self.pos += 2;
                    continue;
                }
                c => text.push(c),
            }
            self.pos += 1;
        }
        flush(&mut text, &mut nodes);
        Ok(nodes)
    }

    /// `__name__` at the cursor: the name, or None where the underscores are text (no closing
    /// `__`, or characters between that no name holds).
    fn wildcard(&mut self) -> Result<Option<String>> {
        let start = self.pos;
        let rest = &self.chars[start + 2..];
        let Some(end) = rest.windows(2).position(|w| w == ['_', '_']) else { return Ok(None) };
        let name: String = rest[..end].iter().collect();
        if name.is_empty() {
            return Err(self.error(start, "`____` names no wildcard"));
        }
        if !name.chars().all(name_char) {
            return Ok(None);
        }
        if name.starts_with('/') || name.split('/').any(|part| part.is_empty() || part == "." || part == "..") {
            return Err(self.error(start, &format!("`__{name}__` must name a file inside the wildcards folder")));
        }
        self.pos = start + 2 + end + 2;
        Ok(Some(name))
    }

    /// `{…}` at the cursor: a category slot or a group of choices.
    fn brace(&mut self, depth: usize) -> Result<Node> {
        let start = self.pos;
        for (slot, node) in [("{category}", Node::Category), ("{categories}", Node::Categories)] {
            let n = slot.chars().count();
            if self.chars.get(start..start + n).is_some_and(|s| s.iter().copied().eq(slot.chars())) {
                self.pos += n;
                return Ok(node);
            }
        }
        if depth + 1 > MAX_DEPTH {
            return Err(self.error(start, &format!("choices nest deeper than {MAX_DEPTH}")));
        }
        self.pos += 1;
        let mut alternatives = Vec::new();
        loop {
            let from = self.pos;
            let nodes = self.sequence(depth + 1)?;
            let written: String = self.chars[from..self.pos].iter().collect();
            alternatives.push(self.weighed(from, written, nodes)?);
            match self.peek() {
                Some('|') => self.pos += 1,
                Some('}') => {
                    self.pos += 1;
                    break;
                }
                _ => return Err(self.error(start, "`{` is not closed (write `\\{` for the character)")),
            }
        }
        if let [only] = &alternatives[..] {
            if only.written.is_empty() {
                return Err(self.error(start, "`{}` has no choices"));
            }
        }
        if alternatives.iter().all(|a| a.weight == 0.0) {
            return Err(self.error(start, "every choice weighs 0"));
        }
        Ok(Node::Group { at: self.at(start), alternatives })
    }

    /// An alternative with its weight: `W::` before its text, W a non-negative number; else 1.
    fn weighed(&self, from: usize, written: String, mut nodes: Vec<Node>) -> Result<Alternative> {
        let Some(Node::Text(first)) = nodes.first_mut() else { return Ok(Alternative { weight: 1.0, written, nodes }) };
        if first.contains("$$") && from > 0 && self.chars[from - 1] == '{' {
            return Err(self.error(from, "`{N$$…}` (several choices at once) is not supported"));
        }
        let Some((weight, rest)) = first.split_once("::") else {
            return Ok(Alternative { weight: 1.0, written, nodes });
        };
        let number = weight.trim();
        let valid = !number.is_empty()
            && number.chars().all(|c| c.is_ascii_digit() || c == '.')
            && number.chars().filter(|&c| c == '.').count() <= 1
            && number.chars().any(|c| c.is_ascii_digit());
        let weight = match number.parse::<f64>() {
            Ok(w) if valid && w.is_finite() => w,
            _ => return Err(self.error(from, &format!("weight `{number}` is not a non-negative number"))),
        };
        let written = written.split_once("::").map_or(written.clone(), |(_, w)| w.to_string());
        *first = rest.to_string();
        if first.is_empty() {
            nodes.remove(0);
        }
        Ok(Alternative { weight, written, nodes })
    }
}

/// Moves the literal text gathered so far into `nodes`.
fn flush(text: &mut String, nodes: &mut Vec<Node>) {
    if !text.is_empty() {
        nodes.push(Node::Text(std::mem::take(text)));
    }
}

#[cfg(test)]
mod tests;
