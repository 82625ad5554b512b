//! `vkdiff dataset`'s refusals: one error line naming what is wrong, before any work, and
//! nothing written.

use super::*;

#[test]
fn bad_dataset_arguments_print_one_error_line_and_write_nothing() {
    let dir = scratch("dataset-bad");
    let out = dir.join("set");
    let foreign = dir.join("foreign");
    std::fs::create_dir_all(&foreign).unwrap();
    std::fs::write(foreign.join("notes.txt"), "mine").unwrap();
    let model = fixture("pipeline/tiny-sdxl");
    let adapter = fixture("workflow/ip-adapter_tiny.safetensors");
    let encoder = fixture("workflow/image_encoder");
    let missing = dir.join("missing.png");
    let missing = missing.to_str().unwrap();
    let base = |out: &Path| {
        ["dataset", "--out", out.to_str().unwrap(), "--model", &model, "--width", "160", "--height", "128"]
            .map(String::from)
            .to_vec()
    };
    for (extra, message) in [
        (vec!["--prompt", "x", "--crops", "2", "--crop-size", "48"], "--crop-size 48 must be a multiple of 32"),
        (vec!["--prompt", "x", "--crops", "2", "--crop-size", "256"], "--crop-size 256 must lie in [1, 128]"),
        (vec!["--crops", "1"], "at least one prompt"),
        (vec!["--prompt", "x", "--prompts", missing], "--prompts"),
        (vec!["--prompt", "x", "--count", "0"], "--count must be at least 1"),
        (vec!["--prompt", "x", "--batch", "0"], "--batch must be at least 1"),
        (vec!["--prompt", "x", "--shard", "2/2"], "--shard 2/2"),
        (vec!["--prompt", "x", "--shards", "2"], "JOB_COMPLETION_INDEX"),
        (
            vec!["--prompt", "x", "--ip-adapter", &adapter, "--image-encoder", &encoder],
            "--ip-adapter needs style images",
        ),
        (
            vec!["--prompt", "x", "--ip-adapter", &adapter, "--image-encoder", &encoder, "--ip-set", missing],
            "--ip-image",
        ),
        (vec!["--prompt", "x", "--sampler", "ddim", "--scheduler", "karras"], "Karras"),
        (vec!["--prompt", "x", "--density", "-1"], "--density"),
        (vec!["--prompt", "x", "--init-strength", "0"], "--init-strength 0 must be in (0, 1]"),
        (vec!["--prompt", "(x:1.2.3)", "--prompt-syntax", "weighted"], "weight `1.2.3`"),
        (vec!["--render-only"], "--render-only makes the shaded renders the images: drop --model"),
        (vec!["--prompt", "x", "--min-free", "100T"], "--min-free keeps 100 TiB"),
        (vec!["--prompt", "x", "--min-free", "lots"], "lots: expected bytes"),
    ] {
        let mut args = base(&out);
        args.extend(extra.iter().map(|s| s.to_string()));
        let result = vk().args(&args).output().unwrap();
        let stderr = String::from_utf8_lossy(&result.stderr);
        let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error")).collect();
        assert!(!result.status.success() && errors.len() == 1 && errors[0].contains(message), "{extra:?}: {stderr}");
        assert!(!out.exists(), "{extra:?} wrote {}", out.display());
    }
    // A render-only set takes no diffusion flag: each is named, not ignored.
    for (flag, value) in [("--prompt", "x"), ("--negative-prompt", "x"), ("--init-strength", "0.5")] {
        let args = ["dataset", "--render-only", "--out", out.to_str().unwrap(), flag, value];
        let stderr = String::from_utf8_lossy(&vk().args(args).output().unwrap().stderr).into_owned();
        let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error")).collect();
        assert!(errors.len() == 1 && errors[0].contains("--render-only") && errors[0].contains(flag), "{stderr}");
        assert!(!out.exists(), "{flag} wrote {}", out.display());
    }
    let mut args = base(&foreign);
    args.extend(["--prompt", "x"].map(String::from));
    let result = vk().args(&args).output().unwrap();
    assert!(
        String::from_utf8_lossy(&result.stderr).contains("holds other files (notes.txt"),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    assert_eq!(std::fs::read_dir(&foreign).unwrap().count(), 1, "nothing written into someone else's folder");
    // A file where the folder should be: the OS's reason, said once.
    let file = dir.join("afile");
    std::fs::write(&file, "mine").unwrap();
    let mut args = base(&file);
    args.extend(["--prompt", "x"].map(String::from));
    let stderr = String::from_utf8_lossy(&vk().args(&args).output().unwrap().stderr).into_owned();
    assert!(stderr.lines().any(|l| l.starts_with("error:") && l.contains("afile")), "{stderr}");
    assert_eq!(stderr.matches("(os error").count(), 1, "the OS's reason repeated: {stderr}");
    let result = vkdiff(&["dataset", "merge", dir.to_str().unwrap()]);
    assert!(String::from_utf8_lossy(&result.stderr).contains("not a vkdiff dataset folder"));
}
