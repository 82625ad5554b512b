//! Models named as users name them: a local path, or a Hugging Face id resolved offline in the
//! cache where `huggingface_hub` keeps downloads, as `from_pretrained(id,
//! local_files_only=True)` finds them. vkdiff never downloads; a model that is not there is one
//! line with the command that downloads it.
//!
//! An id is `ORG/NAME`, `ORG/NAME@REVISION` (a branch, tag or commit) and either followed by
//! `/path/in/repo` for one file or folder of the repository. The cache is `$HF_HUB_CACHE`, else
//! `$HF_HOME/hub`, else `$XDG_CACHE_HOME/huggingface/hub`, else `~/.cache/huggingface/hub`; a
//! repository there is `models--ORG--NAME/` with `refs/REVISION` (a commit hash),
//! `snapshots/COMMIT/` (the repository's files, as links into `blobs/`) and `blobs/`.

use crate::Usage;
use std::path::{Component, Path, PathBuf};
use vkdiff_runtime::Environment;

/// What a model flag takes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wants {
    /// One file (a LoRA, an IP-Adapter): a repository that holds a single `.safetensors` at its
    /// top gives that file.
    File,
    /// A folder (an image encoder).
    Folder,
    /// A diffusers folder or a single file.
    Either,
}

/// The model `text` names for `flag`: the local path when one exists (an id that is also a
/// local path says so on stderr), else the Hugging Face id resolved in the cache `env` points to.
pub fn resolve_model(flag: &str, text: &Path, wants: Wants, env: &Environment) -> anyhow::Result<PathBuf> {
    let cache = hub_cache(env);
    let resolved = resolve_in(flag, text, wants, &cache)?;
    if let Some(note) = resolved.note {
        eprintln!("{note}");
    }
    Ok(resolved.path)
}

/// A resolved model, and a line for the user where a local path shadows an id.
#[derive(Debug)]
pub struct Resolved {
    pub path: PathBuf,
    pub note: Option<String>,
}

/// The hub cache folder as `huggingface_hub` chooses it from `env`'s values as set (an empty
/// one skipped).
pub fn hub_cache(env: &Environment) -> PathBuf {
    let var = |k: &str| env.raw(k).filter(|v| !v.is_empty()).map(|v| expand_home(v, env));
    if let Some(dir) = var("HF_HUB_CACHE").or_else(|| var("HUGGINGFACE_HUB_CACHE")) {
        return dir;
    }
    let home = var("HF_HOME").unwrap_or_else(|| {
        let cache = var("XDG_CACHE_HOME").unwrap_or_else(|| expand_home("~/.cache", env));
        cache.join("huggingface")
    });
    home.join("hub")
}

fn expand_home(path: &str, env: &Environment) -> PathBuf {
    match (path.strip_prefix("~/"), env.raw("HOME")) {
        (Some(rest), Some(home)) => Path::new(&home).join(rest),
        _ => PathBuf::from(path),
    }
}

/// A parsed `ORG/NAME[@REVISION][/PATH]`.
#[derive(Debug, PartialEq, Eq)]
struct HubId {
    repo: String,
    revision: Option<String>,
    inner: Option<String>,
}

impl HubId {
    /// `text` as an id, if it reads as one: two or more plain components, the first two made of
    /// letters, digits, `-`, `_` and `.` (and `@REVISION` on the second).
    fn parse(text: &str) -> Option<HubId> {
        let path = Path::new(text);
        let parts: Vec<&str> = path
            .components()
            .map(|c| match c {
                Component::Normal(p) => p.to_str(),
                _ => None,
            })
            .collect::<Option<_>>()?;
        if parts.len() < 2 || text.ends_with('/') && parts.len() == 2 {
            return None;
        }
        let (name, revision) = match parts[1].split_once('@') {
            Some((name, rev)) if !rev.is_empty() => (name, Some(rev.to_string())),
            Some(_) => return None,
            None => (parts[1], None),
        };
        let plain = |s: &str| {
            !s.is_empty()
                && !s.starts_with(['.', '-'])
                && s.chars().all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
        };
        if !plain(parts[0]) || !plain(name) {
            return None;
        }
        let inner = (parts.len() > 2).then(|| parts[2..].join("/"));
        Some(HubId { repo: format!("{}/{name}", parts[0]), revision, inner })
    }

    fn folder(&self, cache: &Path) -> PathBuf {
        cache.join(format!("models--{}", self.repo.replace('/', "--")))
    }

    /// The `hf download` line that fetches what this id names.
    fn download(&self) -> String {
        let mut line = format!("hf download {}", self.repo);
        match &self.inner {
            Some(file) if Path::new(file).extension().is_some() => line += &format!(" {file}"),
            Some(folder) => line += &format!(" --include '{folder}/*'"),
            None => {}
        }
        if let Some(rev) = &self.revision {
            line += &format!(" --revision {rev}");
        }
        line
    }
}

/// [`resolve_model`] with the cache given (tests give their own).
pub fn resolve_in(flag: &str, text: &Path, wants: Wants, cache: &Path) -> anyhow::Result<Resolved> {
    let id = text.to_str().and_then(HubId::parse);
    let refuse = |why: String| -> anyhow::Error { Usage(format!("{flag} {}: {why}", text.display())).into() };
    if text.exists() {
        let note = id.filter(|id| id.folder(cache).is_dir()).map(|id| {
            format!(
                "note: {flag} {} is the local path ./{}; the Hugging Face cache's {} is not used",
                text.display(),
                text.display(),
                id.repo
            )
        });
        return Ok(Resolved { path: text.to_path_buf(), note });
    }
    if std::fs::symlink_metadata(text).is_ok() {
        return Err(refuse("a link to nothing".into()));
    }
    let Some(id) = id else { return Err(refuse("no such file or folder".into())) };
    let folder = id.folder(cache);
    if !folder.is_dir() {
        return Err(refuse(format!(
            "no such local path, and not in the Hugging Face cache {} (vkdiff never downloads); download it with: {}",
            cache.display(),
            id.download()
        )));
    }
    let revision = id.revision.as_deref().unwrap_or("main");
    let commit = match std::fs::read_to_string(folder.join("refs").join(revision)) {
        Ok(hash) => hash.trim().to_string(),
        Err(_) if folder.join("snapshots").join(revision).is_dir() => revision.to_string(),
        Err(_) => {
            let known = list(&folder.join("refs"));
            return Err(refuse(format!(
                "the Hugging Face cache has no revision `{revision}` of {} (it has: {}); download it with: {}",
                id.repo,
                if known.is_empty() { "none".into() } else { known.join(", ") },
                id.download()
            )));
        }
    };
    let snapshot = folder.join("snapshots").join(&commit);
    if !snapshot.is_dir() {
        return Err(refuse(format!(
            "the Hugging Face cache's {revision} of {} is commit {commit}, whose snapshot is missing; download it \
            again with: {}",
            id.repo,
            id.download()
        )));
    }
    let mut path = id.inner.as_ref().map_or(snapshot.clone(), |inner| snapshot.join(inner));
    if !path.exists() {
        let why = if std::fs::symlink_metadata(&path).is_ok() {
            "a link to a missing blob (an interrupted download?) in"
        } else {
            "not in"
        };
        return Err(refuse(format!(
            "{why} the Hugging Face cache's snapshot {commit} of {}; download it with: {}",
            id.repo,
            id.download()
        )));
    }
    if let Some(broken) = first_broken_link(&path) {
        let name = broken.strip_prefix(&snapshot).unwrap_or(&broken).display().to_string();
        return Err(refuse(format!(
            "{name} in the Hugging Face cache is a link to a missing blob (an interrupted download?); download it \
            again with: hf download {} {name}",
            id.repo
        )));
    }
    if wants == Wants::File && path.is_dir() {
        let files: Vec<String> = list(&path).into_iter().filter(|n| n.ends_with(".safetensors")).collect();
        match files.as_slice() {
            [one] => path = path.join(one),
            _ => {
                return Err(refuse(format!(
                "a folder of the Hugging Face cache with {} .safetensors files at its top ({}): name one, as {}/FILE",
                files.len(),
                files.join(", "),
                text.display()
            )))
            }
        }
    }
    if wants == Wants::Folder && !path.is_dir() {
        return Err(refuse("names a file; this flag takes a folder".into()));
    }
    Ok(Resolved { path, note: None })
}

/// The names in `dir`, sorted (refs may be nested: `refs/pr/1` reads as `pr`).
fn list(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// The first link under `path` (itself included) whose target is missing.
fn first_broken_link(path: &Path) -> Option<PathBuf> {
    let meta = std::fs::symlink_metadata(path).ok()?;
    if meta.file_type().is_symlink() && !path.exists() {
        return Some(path.to_path_buf());
    }
    if !path.is_dir() {
        return None;
    }
    let mut entries: Vec<PathBuf> = std::fs::read_dir(path).ok()?.flatten().map(|e| e.path()).collect();
    entries.sort();
    entries.iter().find_map(|p| first_broken_link(p))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_parse_as_huggingface_names_them() {
        let id = |t: &str| HubId::parse(t);
        assert_eq!(
            id("stabilityai/stable-diffusion-xl-base-1.0"),
            Some(HubId { repo: "stabilityai/stable-diffusion-xl-base-1.0".into(), revision: None, inner: None })
        );
        assert_eq!(
            id("h94/IP-Adapter@main/sdxl_models/ip-adapter_sdxl.safetensors"),
            Some(HubId {
                repo: "h94/IP-Adapter".into(),
                revision: Some("main".into()),
                inner: Some("sdxl_models/ip-adapter_sdxl.safetensors".into())
            })
        );
        for not_ids in ["model.safetensors", "/abs/org/name", "./org/name", "../org/name", "org/na me", "org/name@"] {
            assert_eq!(id(not_ids), None, "{not_ids}");
        }
    }

    #[test]
    fn the_cache_is_where_huggingface_hub_looks() {
        let env = |vars: &[(&str, &str)]| Environment::from_pairs(vars.iter().copied());
        assert_eq!(hub_cache(&env(&[("HF_HUB_CACHE", "/c"), ("HF_HOME", "/h")])), Path::new("/c"));
        assert_eq!(hub_cache(&env(&[("HF_HOME", "/h"), ("HOME", "/home/u")])), Path::new("/h/hub"));
        assert_eq!(hub_cache(&env(&[("HF_HOME", "~/hf"), ("HOME", "/home/u")])), Path::new("/home/u/hf/hub"));
        assert_eq!(hub_cache(&env(&[("XDG_CACHE_HOME", "/x")])), Path::new("/x/huggingface/hub"));
        assert_eq!(hub_cache(&env(&[("HOME", "/home/u")])), Path::new("/home/u/.cache/huggingface/hub"));
    }
}
