//! Renamings from diffusers names to an original (sgm / LDM / OpenCLIP) single-file layout: module
//! prefixes, inner names by table, and single tensors stored under another name or form.

use std::collections::HashMap;

/// How the names below a renamed module map.
#[derive(Clone, Copy)]
pub enum Inner {
    /// Kept as they are.
    Same,
    /// The first component renamed by the table; names it does not list are kept.
    Table(&'static [(&'static str, &'static str)]),
    /// The first component renamed by the table; names it does not list do not exist.
    Strict(&'static [(&'static str, &'static str)]),
}

struct Rule {
    diffusers: String,
    original: String,
    inner: Inner,
}

/// Where a diffusers-named tensor lives in an original-layout file.
#[derive(Clone, Debug, PartialEq)]
pub struct StoredAs {
    pub name: String,
    /// Part `.0` of `.1` equal blocks of rows of the stored tensor (OpenCLIP's fused q/k/v).
    pub rows: Option<(usize, usize)>,
    /// Stored as the transpose (OpenCLIP's `text_projection`, applied as `x @ P`).
    pub transposed: bool,
}

impl StoredAs {
    pub fn plain(name: String) -> StoredAs {
        StoredAs { name, rows: None, transposed: false }
    }
}

/// Maps diffusers names of one network onto the original layout: module prefixes, plus single
/// tensors stored differently.
#[derive(Default)]
pub struct OriginalNames {
    rules: Vec<Rule>,
    exact: HashMap<String, StoredAs>,
    /// Names no rule covers are stored unchanged (else they do not exist in the layout).
    keep_others: bool,
}

impl OriginalNames {
    /// A renaming under which names no rule covers are stored unchanged.
    pub fn keeping_others() -> OriginalNames {
        OriginalNames { keep_others: true, ..Default::default() }
    }

    /// Adds a module rule: `diffusers.*` is stored as `original.*`, inner names mapped by `inner`.
    pub fn module(&mut self, diffusers: &str, original: &str, inner: Inner) {
        self.rules.push(Rule { diffusers: diffusers.into(), original: original.into(), inner });
    }

    /// Adds one tensor stored under another name or form.
    pub fn tensor(&mut self, diffusers: &str, stored: StoredAs) {
        self.exact.insert(diffusers.into(), stored);
    }

    /// Where a diffusers-named tensor is stored, if it belongs to a mapped module.
    pub fn rename(&self, name_in: &str) -> Option<StoredAs> {
        let name = name_in;
        if let Some(s) = self.exact.get(name) {
            return Some(s.clone());
        }
        let name = self.rules.iter().find_map(|r| {
            let rest = name.strip_prefix(r.diffusers.as_str())?.strip_prefix('.')?;
            let (module, tail) = rest.split_once('.').unwrap_or((rest, ""));
            let renamed = match r.inner {
                Inner::Same => None,
                Inner::Table(t) | Inner::Strict(t) => t.iter().find(|(d, _)| *d == module).map(|(_, o)| *o),
            };
            let module = match (renamed, r.inner) {
                (Some(o), _) => o,
                (None, Inner::Strict(_)) => return None,
                (None, _) => module,
            };
            Some(if tail.is_empty() {
                format!("{}.{module}", r.original)
            } else {
                format!("{}.{module}.{tail}", r.original)
            })
        });
        match name {
            Some(n) => Some(StoredAs::plain(n)),
            None if self.keep_others => Some(StoredAs::plain(name_in.to_string())),
            None => None,
        }
    }
}
