//! What the command-line tests share: running the binary and a scratch folder per test.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn vkdiff(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_vkdiff")).args(args).env("RUST_BACKTRACE", "0").output().unwrap()
}

/// An empty folder under the target's temporary directory, unique to this test process.
pub fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A PNG's text chunks, `tEXt` and `iTXt` alike, in file order.
#[allow(dead_code)] // not every test binary reads PNG text
pub fn png_text(path: &Path) -> Vec<(String, String)> {
    let reader = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap())).read_info().unwrap();
    let info = reader.info();
    let latin1 = info.uncompressed_latin1_text.iter().map(|t| (t.keyword.clone(), t.text.clone()));
    latin1.chain(info.utf8_text.iter().map(|t| (t.keyword.clone(), t.get_text().unwrap()))).collect()
}
