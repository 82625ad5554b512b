//! How the tables of failures run: each case a command with a real failure (a bad value, a
//! missing or malformed file, the CPU device refused, a full disk, a file-size limit), its exit
//! code and the words its one error line must hold.

use super::{cli::command, failure_of};
use std::path::Path;
use std::process::Command;

/// One failing run: what it is, the command, the code it must exit with and the words its
/// error line must hold.
pub struct Case {
    what: &'static str,
    command: Command,
    code: i32,
    says: &'static [&'static str],
}

pub fn case(what: &'static str, command: Command, code: i32, says: &'static [&'static str]) -> Case {
    Case { what, command, code, says }
}

/// Runs every case, then fails naming each that exited otherwise or said otherwise.
pub fn check(cases: Vec<Case>) {
    let wrong: Vec<String> = cases
        .into_iter()
        .filter_map(|mut case| {
            let (code, line) = failure_of(&mut case.command);
            let right = code == case.code && case.says.iter().all(|s| line.contains(s));
            (!right).then(|| {
                format!("{}: exit {code}, not {}, or {:?} missing from: {line}", case.what, case.code, case.says)
            })
        })
        .collect();
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

/// `vkdiff args`.
pub fn vkdiff(args: &[&str]) -> Command {
    let mut command = command();
    command.args(args).env("RUST_BACKTRACE", "0");
    command
}

/// `command` run by `program` and `args` (a wrapper that ends by exec'ing it), with its
/// environment.
fn wrapped(program: &str, args: &[&str], command: &Command) -> Command {
    let mut wrapper = Command::new(program);
    wrapper.args(args).arg(command.get_program()).args(command.get_args());
    for (name, value) in command.get_envs() {
        match value {
            Some(value) => wrapper.env(name, value),
            None => wrapper.env_remove(name),
        };
    }
    wrapper
}

/// `vkdiff`'s `command` writing into `mount`, a file system with no byte free: a private tmpfs
/// in a mount namespace of its own (`unshare -rm`: no privilege needed, nothing outlives the
/// run), holding copies of `copies` (each as `mount/<its name>`), then filled to its last page,
/// so that the first byte written there fails as on a full disk (ENOSPC).
pub fn on_full_disk(mount: &Path, copies: &[&Path], command: Command) -> Command {
    std::fs::create_dir_all(mount).unwrap();
    let script = r#"m=$1; shift
        mount -t tmpfs -o size=16m tmpfs "$m" || { echo "error: no tmpfs: the test needs user namespaces"; exit 90; }
        while [ "$1" != -- ]; do cp -r "$1" "$m/" || exit 91; shift; done; shift
        cat /dev/zero >"$m/.filler" 2>/dev/null
        exec "$@""#;
    let mut args = vec!["-rm", "sh", "-c", script, "sh", text(mount)];
    args.extend(copies.iter().map(|c| text(c)));
    args.push("--");
    wrapped("unshare", &args, &command)
}

/// `vkdiff`'s `command` under `ulimit -f 1` (512 bytes a file) with SIGXFSZ ignored, as a job's
/// file-size limit is met: a larger write fails with EFBIG instead of killing the process.
pub fn under_file_size_limit(command: Command) -> Command {
    wrapped("sh", &["-c", r#"trap "" XFSZ; ulimit -f 1; exec "$@""#, "sh"], &command)
}

/// A path's text, for argument lists.
pub fn text(path: &Path) -> &str {
    path.to_str().unwrap()
}
