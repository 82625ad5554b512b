//! The deploy scripts (`deploy/`) as a cluster runs them: the Slurm array and its merge, its
//! requeue on a node without a GPU driver and its refusal of bad input, and the Kubernetes jobs.

use super::*;

/// The test set's flags as an arguments file, as the deploy scripts read them.
fn args_file(dir: &Path) -> PathBuf {
    let flags = dataset_flags(Path::new("unused"));
    let path = dir.join("dataset.args");
    std::fs::write(&path, format!("# the test set\n\n{}\n", flags[3..].join("\n"))).unwrap();
    path
}

/// `script` run by `shell` with the deploy scripts' variables and `env`.
fn deploy(shell: &str, script: &[&str], dir: &Path, args: &Path, env: &[(&str, &str)]) -> std::process::Child {
    let mut command = shielded(Command::new(shell));
    command.args(script).current_dir(env!("CARGO_MANIFEST_DIR"));
    command.envs([
        // The jobs refuse a CPU device, and CI has only lavapipe.
        ("VKDIFF_REQUIRE_GPU", "0"),
        ("VKDIFF", env!("CARGO_BIN_EXE_vkdiff")),
        ("DATASET_DIR", dir.to_str().unwrap()),
        ("DATASET_ARGS", args.to_str().unwrap()),
    ]);
    command.envs(env.iter().copied()).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap()
}

fn wait_ok(child: std::process::Child) {
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
}

#[test]
fn the_slurm_array_and_its_merge_make_the_one_run() {
    let root = scratch("dataset-slurm");
    let (dir, args) = (root.join("set"), args_file(&root));
    for task in ["3", "4"] {
        let env = [("SLURM_ARRAY_TASK_ID", task), ("SLURM_ARRAY_TASK_MIN", "3"), ("SLURM_ARRAY_TASK_COUNT", "2")];
        wait_ok(deploy("bash", &["deploy/slurm/dataset.sbatch"], &dir, &args, &env));
    }
    std::fs::remove_file(dir.join("annotations.json")).unwrap(); // the last task merged; so must the merge job
    wait_ok(deploy("bash", &["deploy/slurm/merge.sbatch"], &dir, &args, &[]));
    assert_same_folder(&dir, reference());
}

/// A stand-in `scontrol` on PATH that notes its arguments in `root/scontrol.log`; the PATH.
fn fake_scontrol(root: &Path) -> String {
    let bin = root.join("bin");
    std::fs::create_dir_all(&bin).unwrap();
    let script = bin.join("scontrol");
    std::fs::write(&script, format!("#!/bin/sh\necho \"$@\" >> {}/scontrol.log\n", root.display())).unwrap();
    std::fs::set_permissions(&script, std::os::unix::fs::PermissionsExt::from_mode(0o755)).unwrap();
    format!("{}:{}", bin.display(), std::env::var("PATH").unwrap_or_default())
}

#[test]
fn the_slurm_task_refuses_a_node_without_a_gpu_driver_and_requeues() {
    let root = scratch("dataset-slurm-cpu");
    let (dir, args) = (root.join("set"), args_file(&root));
    let path = fake_scontrol(&root);
    let env = [("VKDIFF_REQUIRE_GPU", ""), ("PATH", &path), ("SLURM_JOB_ID", "4242")];
    let out = deploy("bash", &["deploy/slurm/dataset.sbatch"], &dir, &args, &env).wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.code() == Some(3) && stderr.contains("error: a GPU is required"), "{stderr}");
    assert!(!dir.join("annotations.json").exists());
    // A device failure may pass on another node: the task is requeued.
    let log = std::fs::read_to_string(root.join("scontrol.log")).unwrap_or_default();
    assert_eq!(log.trim(), "requeue 4242", "{stderr}");
}

#[test]
fn the_slurm_task_fails_bad_input_without_requeueing() {
    let root = scratch("dataset-slurm-bad");
    let dir = root.join("set");
    let args = root.join("bad.args");
    std::fs::write(&args, "--crop-size\n48\n--crops\n2\n--prompt\nx\n--model\n/nowhere\n").unwrap();
    let path = fake_scontrol(&root);
    let env = [("PATH", path.as_str()), ("SLURM_JOB_ID", "4243")];
    let out = deploy("bash", &["deploy/slurm/dataset.sbatch"], &dir, &args, &env).wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(!root.join("scontrol.log").exists(), "bad input was requeued: {stderr}");
}

#[test]
fn the_kubernetes_job_fails_at_once_on_bad_input() {
    // podFailurePolicy: exit 2 fails the Job; it needs restartPolicy Never.
    let yaml =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("deploy/kubernetes/dataset-job.yaml"))
            .unwrap();
    let rules: String = yaml.lines().skip_while(|l| !l.contains("podFailurePolicy:")).take(12).collect();
    assert!(rules.contains("action: FailJob") && rules.contains("values: [2]"), "{rules}");
    assert!(rules.contains("containerName: vkdiff") && yaml.contains("- name: vkdiff\n"), "{rules}");
    assert!(yaml.contains("restartPolicy: Never") && !yaml.contains("restartPolicy: OnFailure"));
}

#[test]
fn the_kubernetes_indexed_job_makes_the_one_run() {
    let root = scratch("dataset-k8s");
    let (dir, args) = (root.join("set"), args_file(&root));
    // The pod's shell script, as the Job's container runs it.
    let yaml =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("deploy/kubernetes/dataset-job.yaml"))
            .unwrap();
    let lines: Vec<&str> = yaml.lines().collect();
    let start = lines.iter().position(|l| l.trim() == "- |").expect("the Job runs a script") + 1;
    let indent = lines[start].len() - lines[start].trim_start().len();
    let script: Vec<&str> =
        lines[start..].iter().take_while(|l| l.len() - l.trim_start().len() >= indent).map(|l| &l[indent..]).collect();
    let script = script.join("\n");
    let pods: Vec<_> = ["0", "1"]
        .iter()
        .map(|&index| deploy("sh", &["-c", &script], &dir, &args, &[("JOB_COMPLETION_INDEX", index), ("SHARDS", "2")]))
        .collect();
    pods.into_iter().for_each(wait_ok);
    assert_same_folder(&dir, reference());
}
