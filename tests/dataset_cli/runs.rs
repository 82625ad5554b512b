//! One folder whatever the batch size, the memory budget, the sharding or a kill.

use super::*;

/// Batches of two give the folder of batches of one; so they do under a memory budget that holds
/// the weights, the recorded passes and a decode, but not all three at once (about 11, 1 and 5 MiB
/// with the tiny models): the passes are then freed before each decode and recorded again.
#[test]
fn batches_give_the_same_folder_with_or_without_room_to_keep_their_passes() {
    let recordings = |text: &str| {
        let count = text.split("(recorded ").nth(1).and_then(|t| t.split('×').next());
        count.and_then(|n| n.parse::<usize>().ok()).unwrap_or_else(|| panic!("no recording count: {text}"))
    };
    let mut counts = Vec::new();
    for budget in ["", "17M"] {
        let dir = scratch(&format!("dataset-batch{budget}")).join("set");
        let mut args = dataset_flags(&dir);
        args.extend(["--batch", "2"].map(String::from));
        counts.push(recordings(&run_ok(&args, &[("VKDIFF_MEMORY_BUDGET", budget)])));
        assert_same_folder(&dir, reference());
    }
    assert!(counts[1] > counts[0], "recordings with room and without: {counts:?}");
}

#[test]
fn two_shards_and_a_merge_give_the_one_run() {
    let dir = scratch("dataset-shards").join("set");
    let spawn = |extra: &[&str], env: &[(&str, &str)]| {
        let mut args = dataset_flags(&dir);
        args.extend(extra.iter().map(|s| s.to_string()));
        vk().args(&args).envs(env.iter().copied()).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap()
    };
    // Two processes on one folder at once: one told its shard, one taking it from Slurm.
    let first = spawn(&["--shard", "0/2"], &[]);
    let second =
        spawn(&[], &[("SLURM_ARRAY_TASK_ID", "8"), ("SLURM_ARRAY_TASK_MIN", "7"), ("SLURM_ARRAY_TASK_COUNT", "2")]);
    for child in [first, second] {
        let out = child.wait_with_output().unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    }
    let merged = vkdiff(&["dataset", "merge", dir.to_str().unwrap()]);
    assert!(merged.status.success(), "{}", String::from_utf8_lossy(&merged.stderr));
    assert_same_folder(&dir, reference());

    // A missing part and a part made with other settings are refused, naming them.
    let record = dir.join("records/000003.json");
    let aside = dir.join("aside.json");
    std::fs::rename(&record, &aside).unwrap();
    let refused = vkdiff(&["dataset", "merge", dir.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(
        !refused.status.success()
            && stderr.contains("1 of 6 images are not done")
            && stderr.contains("image 3 (scene 1)"),
        "{stderr}"
    );
    let text = std::fs::read_to_string(&aside).unwrap();
    let fingerprint = read_json(&aside)["fingerprint"].as_str().unwrap().to_string();
    std::fs::write(&record, text.replace(&fingerprint, "0123456789abcdef")).unwrap();
    let refused = vkdiff(&["dataset", "merge", dir.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(
        !refused.status.success() && stderr.contains("records/000003.json was made with other settings"),
        "{stderr}"
    );
    std::fs::rename(&aside, &record).unwrap();

    // So is a run with other settings into the folder, before it writes anything.
    let before = tree(&dir);
    let mut other = dataset_flags(&dir);
    other.extend(["--cfg", "3"].map(String::from));
    let refused = vk().args(&other).output().unwrap();
    let stderr = String::from_utf8_lossy(&refused.stderr);
    let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
    assert!(
        !refused.status.success() && errors.len() == 1 && errors[0].contains("--cfg was 5.0 there, 3.0 now"),
        "{stderr}"
    );
    assert!(tree(&dir) == before, "a refused run changed the folder");
}

#[test]
fn a_killed_run_resumes_to_the_same_folder() {
    let dir = scratch("dataset-kill").join("set");
    let mut child = vk().args(dataset_flags(&dir)).stdout(Stdio::null()).stderr(Stdio::null()).spawn().unwrap();
    let count = || finished_images(&dir);
    while count() < 2 && child.try_wait().unwrap().is_none() {
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let done = count();
    assert!((2..IMAGES as usize).contains(&done), "the run was to be killed part-way, {done} images were done");
    assert!(!dir.join("annotations.json").exists());
    let log = run_ok(&dataset_flags(&dir), &[]);
    assert!(log.contains(&format!("{} to make, {done} already done", IMAGES as usize - done)), "{log}");
    assert_same_folder(&dir, reference());
}
