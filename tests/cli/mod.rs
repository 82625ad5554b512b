//! What the command-line tests share: running the binary and a scratch folder per test.

use std::path::Path;
use std::process::{Command, Output};

pub fn vkdiff(args: &[&str]) -> Output {
    vkdiff_with(args, &[])
}

/// `vkdiff` with these environment variables set as well.
pub fn vkdiff_with(args: &[&str], env: &[(&str, &str)]) -> Output {
    command().args(args).env("RUST_BACKTRACE", "0").envs(env.iter().copied()).output().unwrap()
}

/// The binary, started as cargo starts the test binaries: through the target's runner where one
/// is set (CI's Mesa 26.1 root runs both with its own libraries).
pub fn command() -> Command {
    match std::env::var_os("CARGO_TARGET_X86_64_UNKNOWN_LINUX_GNU_RUNNER") {
        Some(runner) => {
            let mut command = Command::new(runner);
            command.arg(env!("CARGO_BIN_EXE_vkdiff"));
            command
        }
        None => Command::new(env!("CARGO_BIN_EXE_vkdiff")),
    }
}

/// The one `error:` line of a failed run with these environment variables.
#[allow(dead_code)] // for the tests of refusals
pub fn error_line_with(args: &[&str], env: &[(&str, &str)]) -> String {
    let result = vkdiff_with(args, env);
    let stderr = String::from_utf8_lossy(&result.stderr).into_owned();
    let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
    assert!(!result.status.success() && errors.len() == 1, "{args:?}: {stderr}");
    errors[0].to_string()
}

#[allow(unused_imports)] // not every test binary writes files
pub use vkdiff_testkit::scratch;

/// A PNG's text chunks, `tEXt` and `iTXt` alike, in file order.
#[allow(dead_code)] // not every test binary reads PNG text
pub fn png_text(path: &Path) -> Vec<(String, String)> {
    let reader = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap())).read_info().unwrap();
    let info = reader.info();
    let latin1 = info.uncompressed_latin1_text.iter().map(|t| (t.keyword.clone(), t.text.clone()));
    latin1.chain(info.utf8_text.iter().map(|t| (t.keyword.clone(), t.get_text().unwrap()))).collect()
}

/// A PNG's pixels as decoded, row-major.
#[allow(dead_code)] // not every test binary reads pixels
pub fn png_pixels(path: &Path) -> Vec<u8> {
    let mut reader =
        png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap())).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    buf.truncate(info.buffer_size());
    buf
}

/// A render-only set (no model) of `count` scenes of `width`×`height` from seed 11, two
/// `crop`² crops each.
#[allow(dead_code)] // for the tests that read dataset folders
pub fn render_set_of(dir: &Path, count: u64, width: u32, height: u32, crop: u32) {
    let numbers = [count, width as u64, height as u64, crop as u64].map(|n| n.to_string());
    let mut args = vec!["dataset", "--render-only", "--out", dir.to_str().unwrap(), "--seed", "11", "--crops", "2"];
    for (flag, value) in ["--count", "--width", "--height", "--crop-size"].iter().zip(&numbers) {
        args.extend([*flag, value.as_str()]);
    }
    let out = vkdiff(&args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

/// Every file below `dir`, by relative path.
#[allow(dead_code)] // for the tests that compare folders
pub fn tree(dir: &Path) -> std::collections::BTreeMap<String, Vec<u8>> {
    let mut files = std::collections::BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(at) = stack.pop() {
        for entry in std::fs::read_dir(&at).unwrap().flatten() {
            let path = entry.path();
            if path.is_dir() {
                stack.push(path);
            } else {
                let name = path.strip_prefix(dir).unwrap().to_string_lossy().into_owned();
                files.insert(name, std::fs::read(&path).unwrap());
            }
        }
    }
    files
}

/// Debian's chromium (or `VKDIFF_CHROMIUM`); the test fails, naming the package, without it.
#[allow(dead_code)] // for the tests that look at pages
pub fn chromium() -> String {
    let candidates = std::env::var("VKDIFF_CHROMIUM").into_iter().chain(["chromium".into(), "chromium-browser".into()]);
    for candidate in candidates {
        if Command::new(&candidate).arg("--version").output().is_ok_and(|o| o.status.success()) {
            return candidate;
        }
    }
    panic!("headless Chromium is needed to look at the pages vkdiff writes: apt-get install chromium (or set VKDIFF_CHROMIUM)");
}

/// A 1200×900 screenshot of `url`, decoded to RGB.
#[allow(dead_code)] // for the tests that look at pages
pub fn screenshot(browser: &str, url: &str, out: &Path) -> Vec<[u8; 3]> {
    let status = Command::new(browser)
        .args(["--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars", "--window-size=1200,900"])
        .arg(format!("--screenshot={}", out.display()))
        .arg(url)
        .output()
        .unwrap();
    assert!(status.status.success() && out.is_file(), "{}", String::from_utf8_lossy(&status.stderr));
    let image = vkdiff_pipeline::images::read_image(out).unwrap();
    image.pixels.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect()
}

#[allow(dead_code)] // for the tests that read preview pages
/// The bytes of a base64 `data:` URI's payload.
pub fn base64(text: &str) -> Vec<u8> {
    let value = |c: u8| "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/".bytes().position(|d| d == c);
    let sextets: Vec<u32> = text.bytes().filter_map(value).map(|v| v as u32).collect();
    let mut bytes = Vec::new();
    for chunk in sextets.chunks(4) {
        let n = chunk.iter().enumerate().fold(0u32, |n, (k, &s)| n | s << (18 - 6 * k));
        bytes.extend(&n.to_be_bytes()[1..chunk.len()]);
    }
    bytes
}

#[allow(dead_code)] // for the tests that read preview pages
/// An RGBA PNG's width and pixels.
pub fn rgba(png_bytes: &[u8]) -> (usize, Vec<[u8; 4]>) {
    let mut reader = png::Decoder::new(std::io::Cursor::new(png_bytes)).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgba);
    (info.width as usize, buf[..info.buffer_size()].chunks(4).map(|p| [p[0], p[1], p[2], p[3]]).collect())
}

#[allow(dead_code)] // for the tests that read preview pages
/// The PNG of each `<img class="CLASS">` of a preview page, in order.
pub fn layer_pngs(page: &str, class: &str) -> Vec<Vec<u8>> {
    let marker = format!("<img class=\"{class}\" src=\"data:image/png;base64,");
    page.split(&marker).skip(1).map(|rest| base64(&rest[..rest.find('"').unwrap()])).collect()
}
