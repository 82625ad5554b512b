//! The product at few steps: a set made with SDXL-Lightning's recipe (a swapped UNet, Euler on
//! trailing timesteps, no guidance) beside the ControlNet, IP-Adapter and LoRAs, stopped and
//! resumed; and the warning a distillation run outside its recipe gets.

use super::*;

/// The tiny "distilled" UNet under the name SDXL-Lightning publishes its 4-step UNet as.
fn lightning_unet(dir: &Path) -> String {
    let path = dir.join("sdxl_lightning_4step_unet.safetensors");
    std::fs::copy(fixture("few_step/unet-diffusers.safetensors"), &path).unwrap();
    path.to_str().unwrap().to_string()
}

/// `dataset_flags` with two scenes under Lightning's recipe.
fn lightning_flags(out: &Path, unet: &str) -> Vec<String> {
    let mut args = dataset_flags(out);
    let at = |flag: &str, args: &[String]| args.iter().position(|a| a == flag).unwrap() + 1;
    let (count, steps, sampler) = (at("--count", &args), at("--steps", &args), at("--sampler", &args));
    args[count] = "2".into();
    args[steps] = "4".into();
    args[sampler] = "euler".into();
    args.extend(["--timestep-spacing", "trailing", "--cfg", "0", "--unet", unet].map(String::from));
    args
}

#[test]
fn a_lightning_set_stopped_and_resumed_is_the_one_run() {
    let root = scratch("dataset-lightning");
    let unet = lightning_unet(&root);
    let whole = root.join("whole");
    let log = run_ok(&lightning_flags(&whole, &unet), &[]);
    assert!(!log.contains("warning:"), "a run within the recipe was warned: {log}");
    let settings = &read_json(&whole.join("dataset.json"))["settings"];
    assert_eq!(
        (&settings["unet"], &settings["timestep-spacing"], &settings["sampler"]),
        (&Value::from(unet.clone()), &Value::from("trailing"), &Value::from("euler"))
    );

    // Stopped after its first image by the SIGTERM a scheduler sends, then run again.
    let dir = root.join("set");
    let mut child =
        vk().args(lightning_flags(&dir, &unet)).stdout(Stdio::null()).stderr(Stdio::null()).spawn().unwrap();
    let count = || finished_images(&dir);
    while count() < 1 && child.try_wait().unwrap().is_none() {
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    let stopped = Command::new("kill").args(["-TERM", &child.id().to_string()]).status().unwrap();
    assert!(stopped.success());
    let status = child.wait().unwrap();
    let done = count();
    assert!(done < 4 && !status.success(), "the run was to stop part-way: {done} images, {status}");
    let log = run_ok(&lightning_flags(&dir, &unet), &[]);
    assert!(log.contains(&format!("{} to make, {done} already done", 4 - done)), "{log}");
    assert_same_folder(&dir, &whole);
}

#[test]
fn a_distillation_outside_its_recipe_is_warned_once_before_any_work() {
    let root = scratch("recipe-warning");
    let unet = lightning_unet(&root);
    let gen = |extra: &[&str]| {
        let mut args: Vec<String> = ["gen", "--prompt", "mushrooms", "--out"].map(String::from).to_vec();
        args.push(root.join("out.png").to_str().unwrap().into());
        args.extend(
            ["--model", &fixture("pipeline/tiny-sdxl"), "--unet", &unet, "--width", "64", "--height", "64"]
                .map(String::from),
        );
        // --require-gpu stops the run at the device, after the settings are checked.
        args.extend(extra.iter().map(|s| s.to_string()).chain(["--require-gpu".into()]));
        let out = vk().args(&args).output().unwrap();
        String::from_utf8_lossy(&out.stderr)
            .lines()
            .filter(|l| l.starts_with("warning:"))
            .map(String::from)
            .collect::<Vec<_>>()
    };
    let warned = gen(&["--sampler", "dpmpp_2m", "--steps", "4"]);
    assert_eq!(warned.len(), 1, "{warned:?}");
    let line = &warned[0];
    for part in [
        "sdxl_lightning_4step_unet.safetensors is SDXL-Lightning",
        "--sampler euler --timestep-spacing trailing --cfg 0",
        "this run has --sampler dpmpp_2m, leading timesteps, --cfg 5",
    ] {
        assert!(line.contains(part), "{part:?} not in {line}");
    }
    assert_eq!(gen(&["--steps", "4", "--timestep-spacing", "trailing", "--cfg", "0"]), Vec::<String>::new());
    assert_eq!(gen(&["--steps", "4", "--timestep-spacing", "trailing", "--cfg", "1"]), Vec::<String>::new());
}
