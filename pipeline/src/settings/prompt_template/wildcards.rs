//! Wildcard files: `__name__` is a line of `name.txt` in the wildcards folder (`__a/b__`:
//! `a/b.txt`), one choice a line, blank lines and lines starting with `#` skipped, each line
//! trimmed and itself a template. The files a run's templates name are read and parsed once,
//! before anything loads, with every reference followed: a missing or empty file, a cycle or
//! a chain deeper than [`MAX_DEPTH`] is refused then.

use super::{expand::no_scene, parse_nodes, walk, Node, Origin, PromptTemplate, MAX_DEPTH};
use crate::error::{Error, Result};
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use vkdiff_setting::Message;

/// A wildcard file's lines, each as written and parsed.
type Lines = Vec<(String, Vec<Node>)>;

/// The wildcard files a run's templates read.
#[derive(Clone, Debug, Default)]
pub struct Wildcards {
    dir: Option<PathBuf>,
    files: BTreeMap<String, Lines>,
    /// FNV-1a (64 bits) of every file read: its name and bytes, in name order.
    digest: u64,
}

/// FNV-1a's offset basis and prime, 64 bits.
const FNV_BASIS: u64 = 0xcbf2_9ce4_8422_2325;
const FNV_PRIME: u64 = 0x0100_0000_01b3;

impl Wildcards {
    /// Reads from `dir` every wildcard file `templates` name, and those their lines name.
    pub fn load(dir: Option<&Path>, templates: &[&PromptTemplate]) -> Result<Wildcards> {
        let mut wildcards = Wildcards { dir: dir.map(Path::to_path_buf), files: BTreeMap::new(), digest: FNV_BASIS };
        let mut bytes = BTreeMap::new();
        let mut wanted: Vec<(String, &str)> =
            (templates.iter()).flat_map(|t| t.wildcards().into_iter().map(|n| (n.to_string(), t.text()))).collect();
        while let Some((name, template)) = wanted.pop() {
            if wildcards.files.contains_key(&name) {
                continue;
            }
            let Some(dir) = dir else {
                return Err(Error::Setting(
                    Message::setting("prompt")
                        .then(format!(" \"{template}\": __{name}__ needs "))
                        .and("wildcards")
                        .then(" DIR, the folder of its file"),
                ));
            };
            let (text, lines) = read_file(dir, &name)?;
            for (_, nodes) in &lines {
                walk(nodes, &mut |n| {
                    if let Node::Wildcard(inner) = n {
                        wanted.push((inner.clone(), template));
                    }
                });
            }
            bytes.insert(name.clone(), text);
            wildcards.files.insert(name, lines);
        }
        for (name, text) in &bytes {
            for b in name.bytes().chain([0]).chain(text.bytes()).chain([0]) {
                wildcards.digest = (wildcards.digest ^ b as u64).wrapping_mul(FNV_PRIME);
            }
        }
        let mut heights = HashMap::new();
        for name in wildcards.files.keys() {
            wildcards.height(name, &mut Vec::new(), &mut heights)?;
        }
        Ok(wildcards)
    }

    /// How deep the wildcards below `name` go (itself 1); a cycle, or a chain deeper than
    /// [`MAX_DEPTH`], is refused naming the chain.
    fn height<'a>(
        &'a self,
        name: &'a str,
        chain: &mut Vec<&'a str>,
        heights: &mut HashMap<&'a str, usize>,
    ) -> Result<usize> {
        if let Some(&h) = heights.get(name) {
            return Ok(h);
        }
        let refuse = |chain: &[&str], why: &str| {
            let chain: Vec<String> = chain.iter().chain([&name]).map(|n| format!("__{n}__")).collect();
            Err(Error::Setting(Message::setting("wildcards").then(format!(": {} {why}", chain.join(" → ")))))
        };
        if chain.contains(&name) {
            return refuse(chain, "is a cycle");
        }
        if chain.len() >= MAX_DEPTH {
            return refuse(chain, &format!("nests deeper than {MAX_DEPTH}"));
        }
        chain.push(name);
        let mut inner = Vec::new();
        for (_, nodes) in &self.files[name] {
            walk(nodes, &mut |n| {
                if let Node::Wildcard(w) = n {
                    inner.push(w.as_str());
                }
            });
        }
        let mut height = 1;
        for w in inner {
            height = height.max(1 + self.height(w, chain, heights)?);
        }
        chain.pop();
        heights.insert(name, height);
        Ok(height)
    }

    /// The folder, where one was given.
    pub fn dir(&self) -> Option<&Path> {
        self.dir.as_deref()
    }

    /// A digest of every file read, as 16 hex digits: a resumed dataset is refused when its
    /// wildcard files changed.
    pub fn digest(&self) -> String {
        format!("{:016x}", self.digest)
    }

    /// The lines of wildcard `name`, read by [`Wildcards::load`] for `template`.
    pub(super) fn lines(&self, name: &str, template: &str) -> Result<&Lines> {
        self.files.get(name).ok_or_else(|| {
            Error::Config(format!("prompt \"{template}\": the wildcard __{name}__ was not read for this template"))
        })
    }

    /// Every node `template` can reach: its own and its wildcards' lines', in reading order.
    fn reach<'a>(&'a self, template: &'a PromptTemplate, visit: &mut dyn FnMut(&'a Node)) {
        let mut seen = std::collections::HashSet::new();
        let mut texts: Vec<&[Node]> = vec![&template.nodes];
        while let Some(nodes) = texts.pop() {
            walk(nodes, &mut |n| {
                visit(n);
                if let Node::Wildcard(name) = n {
                    if seen.insert(name.as_str()) {
                        texts.extend(self.files.get(name).into_iter().flatten().map(|(_, nodes)| nodes.as_slice()));
                    }
                }
            });
        }
    }

    /// Whether `template` or a wildcard it reaches fills `{category}` or `{categories}`.
    pub fn uses_categories(&self, template: &PromptTemplate) -> bool {
        let mut uses = false;
        self.reach(template, &mut |n| uses |= matches!(n, Node::Category | Node::Categories));
        uses
    }

    /// Refuses a template with a category slot where there is no scene (`vkdiff gen`).
    pub fn check_no_scene(&self, template: &PromptTemplate) -> Result<()> {
        match self.uses_categories(template) {
            true => Err(no_scene(template.text())),
            false => Ok(()),
        }
    }

    /// Every piece of literal text `template` can put in a prompt: what the prompt syntax checks
    /// before anything loads.
    pub fn literals<'a>(&'a self, template: &'a PromptTemplate) -> Vec<&'a str> {
        let mut texts = Vec::new();
        self.reach(template, &mut |n| {
            if let Node::Text(t) = n {
                texts.push(t.as_str());
            }
        });
        texts
    }
}

/// The text of wildcard `name`'s file in `dir`, and its lines parsed.
fn read_file(dir: &Path, name: &str) -> Result<(String, Lines)> {
    let file = format!("{name}.txt");
    let path = dir.join(&file);
    let refuse =
        |why: String| Error::Setting(Message::setting("wildcards").then(format!(" {}: {why}", path.display())));
    let text = std::fs::read_to_string(&path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => refuse(format!("no such file, for __{name}__")),
        _ => refuse(e.to_string()),
    })?;
    let mut lines = Vec::new();
    for (k, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        lines.push((line.to_string(), parse_nodes(line, Origin::Line { file: &file, line: k + 1 })?));
    }
    if lines.is_empty() {
        return Err(refuse(format!("holds no choice for __{name}__ (blank lines and # comments are skipped)")));
    }
    Ok((text, lines))
}
