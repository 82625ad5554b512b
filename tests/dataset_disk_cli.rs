//! `vkdiff dataset` on a nearly full file system: a private 1 MiB tmpfs (a mount namespace of
//! its own, `unshare -rm`, so no privilege is needed and nothing outlives the test). The run
//! estimates the set's size, stops cleanly once the images left cannot fit beside `--min-free`,
//! and, the space grown, resumes to the folder an unhindered run makes.

mod cli;

use cli::{render_set_of, scratch, tree};
use std::process::Command;

#[test]
fn a_run_stops_before_the_disk_is_full_and_resumes_once_there_is_room() {
    let dir = scratch("disk");
    let reference = dir.join("reference");
    render_set_of(&reference, 12, 320, 256, 128);
    let (mount, copy) = (dir.join("mnt"), dir.join("copy"));
    std::fs::create_dir_all(&mount).unwrap();
    let run = format!(
        "{} dataset --render-only --out {}/set --count 12 --seed 11 --crops 2 --width 320 --height 256 --crop-size 128 \
         --min-free 64K",
        env!("CARGO_BIN_EXE_vkdiff"),
        mount.display()
    );
    // Full, then records and partial files counted, then the space grown and the run resumed.
    let script = format!(
        "set -u; mount -t tmpfs -o size=1m tmpfs {m} || exit 90; {run} 2>{d}/full.err; echo $? >{d}/full.rc; \
         ls {m}/set/records | wc -l >{d}/records; find {m}/set -name '.*partial*' | wc -l >{d}/partials; \
         mount -o remount,size=16m {m} && {run} 2>{d}/resumed.err && cp -r {m}/set {c}",
        m = mount.display(),
        d = dir.display(),
        c = copy.display()
    );
    let out = Command::new("unshare").args(["-rm", "sh", "-c", &script]).output().expect("unshare (util-linux) runs");
    assert!(
        out.status.code() != Some(90),
        "mounting a tmpfs in a user namespace failed; the test needs user namespaces: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let read = |name: &str| std::fs::read_to_string(dir.join(name)).unwrap_or_default();
    let full = read("full.err");
    let errors: Vec<&str> = full.lines().filter(|l| l.starts_with("error")).collect();
    assert_eq!(read("full.rc").trim(), "4", "a resumable stop exits 4: {full}");
    assert!(
        errors.len() == 1 && errors[0].contains("stopped before filling the disk") && errors[0].contains("free"),
        "{full}"
    );
    assert!(!full.contains("No space left"), "the disk filled: {full}");
    assert!(full.contains("estimated size of the whole set"), "{full}");
    let records: usize = read("records").trim().parse().unwrap();
    assert!((1..24).contains(&records), "{records} images before the stop");
    assert_eq!(read("partials").trim(), "0", "a half-written file was left");
    assert!(out.status.success(), "the resumed run failed: {}", read("resumed.err"));
    assert!(tree(&copy) == tree(&reference), "the resumed set differs from an unhindered run's");
}
