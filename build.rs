//! `VKDIFF_VERSION`: the crate version plus the commit the binary is built from
//! (`0.2.0+9f9bdc8`, `-dirty` with uncommitted changes to tracked files), the crate version
//! alone outside a git checkout. Datasets, PNGs and the FID cache record it, since another
//! commit's kernels may give other bytes.

use std::path::Path;
use std::process::Command;

fn main() {
    let crate_version = env!("CARGO_PKG_VERSION");
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let version = match commit(root) {
        Some(commit) => format!("{crate_version}+{commit}"),
        None => crate_version.to_string(),
    };
    println!("cargo:rustc-env=VKDIFF_VERSION={version}");
    // A new commit moves HEAD or its branch; an edit to a tracked file changes `-dirty`, so
    // every source folder is watched too (cargo compares their files' times).
    let git = root.join(".git");
    for watched in ["HEAD", "index", "refs", "packed-refs"] {
        println!("cargo:rerun-if-changed={}", git.join(watched).display());
    }
    let sources = std::fs::read_dir(root).into_iter().flatten().flatten().map(|e| e.path());
    for path in sources.filter(|p| p.join("Cargo.toml").is_file() || p.ends_with("src")) {
        println!("cargo:rerun-if-changed={}", path.display());
    }
    println!("cargo:rerun-if-changed=Cargo.toml");
}

/// `git describe --always --dirty`, tags left out so that it is the commit alone.
fn commit(root: &Path) -> Option<String> {
    let out = Command::new("git")
        .args(["describe", "--always", "--dirty", "--abbrev=10", "--exclude=*"])
        .current_dir(root)
        .output()
        .ok()?;
    let text = String::from_utf8(out.stdout).ok()?;
    let text = text.trim();
    (out.status.success() && !text.is_empty()).then(|| text.to_string())
}
