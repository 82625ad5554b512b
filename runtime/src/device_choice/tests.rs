use super::*;
use crate::device::tests::device;

fn env_of(pairs: &[(&str, &str)]) -> Environment {
    Environment::from_pairs(pairs.iter().copied())
}

/// `choice`'s flags with `env` as the edge reads them, then the device chosen.
fn pick(devices: &[DeviceInfo], choice: &DeviceChoice, env: &[(&str, &str)]) -> Result<usize> {
    let choice = DeviceChoice::from_environment(choice.device.clone(), choice.require_gpu, &env_of(env))?;
    choose(devices, &choice)
}

/// A node with lavapipe first and two NVIDIA GPUs enumerated against their PCI order.
fn node() -> Vec<DeviceInfo> {
    let mut cpu = device(0, DeviceKind::Cpu, true);
    cpu.name = "llvmpipe".into();
    let mut gpus = [1, 2].map(|i| device(i, DeviceKind::Discrete, true));
    for (gpu, bus) in gpus.iter_mut().zip([0xc1, 0x41]) {
        gpu.vendor_id = NVIDIA;
        gpu.pci = Some(PciAddress { domain: 0, bus, device: 0, function: 0 });
    }
    gpus[0].uuid = *b"\x6f\x3c\x1e\x2a\x00\x11\x22\x33\x44\x55\x66\x77\x88\x99\xaa\xbb";
    let mut all = vec![cpu];
    all.extend(gpus);
    all
}

#[test]
fn parses_indices_uuids_and_pci_addresses() {
    assert_eq!("2".parse(), Ok(DeviceSpec::Index(2)));
    assert_eq!("GPU-6F3C1E2A-0011-2233".parse(), Ok(DeviceSpec::Uuid("6f3c1e2a00112233".into())));
    let pci = PciAddress { domain: 0, bus: 0x65, device: 0, function: 0 };
    assert_eq!("0000:65:00.0".parse(), Ok(DeviceSpec::Pci(pci)));
    assert_eq!("65:00.0".parse(), Ok(DeviceSpec::Pci(pci)));
    assert_eq!(pci.to_string(), "0000:65:00.0");
    for bad in ["", "gpu", "65:00", "1234567", "GPU-xyz12345", "1:2:3:4.0"] {
        let err = bad.parse::<DeviceSpec>().unwrap_err();
        assert!(err.contains("names no device"), "{bad}: {err}");
    }
}

#[test]
fn prefers_discrete_then_integrated_then_cpu() {
    let devs = [
        device(0, DeviceKind::Cpu, true),
        device(1, DeviceKind::Integrated, true),
        device(2, DeviceKind::Discrete, true),
    ];
    let auto = DeviceChoice::default();
    assert_eq!(pick(&devs, &DeviceChoice::index(0), &[]).unwrap(), 0);
    assert_eq!(pick(&devs, &auto, &[]).unwrap(), 2);
    assert_eq!(pick(&devs[..2], &auto, &[]).unwrap(), 1);
    assert_eq!(pick(&devs[..1], &auto, &[]).unwrap(), 0);
}

#[test]
fn skips_unusable_devices_and_rejects_them_when_asked() {
    let devs = [device(0, DeviceKind::Discrete, false), device(1, DeviceKind::Cpu, true)];
    assert_eq!(pick(&devs, &DeviceChoice::default(), &[]).unwrap(), 1);
    let err = pick(&devs, &DeviceChoice::index(0), &[]).unwrap_err().to_string();
    assert!(err.contains("dev0") && err.contains("subgroup"), "{err}");
    let err = pick(&devs, &DeviceChoice::index(5), &[]).unwrap_err().to_string();
    assert!(err.contains("only 2"), "{err}");
    assert!(matches!(pick(&[], &DeviceChoice::default(), &[]), Err(Error::NoDevice)));
}

#[test]
fn a_device_without_what_the_kernels_declare_is_refused_by_name() {
    let mut dev = device(0, DeviceKind::Discrete, true);
    dev.zero_init_workgroup = false;
    let err = pick(&[dev], &DeviceChoice::index(0), &[]).unwrap_err().to_string();
    assert!(err.contains("shaderZeroInitializeWorkgroupMemory"), "{err}");
    let mut dev = device(0, DeviceKind::Discrete, true);
    dev.storage_16bit = false;
    assert!(!dev.supports_f16(), "f16 kernels need 16-bit storage access");
}

#[test]
fn finds_devices_by_uuid_and_pci_address() {
    let devs = node();
    let by = |spec: &str| DeviceChoice { device: Some(spec.parse().unwrap()), ..DeviceChoice::default() };
    assert_eq!(pick(&devs, &by("GPU-6f3c1e2a-0011-2233-4455-66778899aabb"), &[]).unwrap(), 1);
    assert_eq!(pick(&devs, &by("6f3c1e2a"), &[]).unwrap(), 1);
    assert_eq!(pick(&devs, &by("0000:41:00.0"), &[]).unwrap(), 2);
    assert_eq!(devs[1].uuid_text(), "6f3c1e2a-0011-2233-4455-66778899aabb");
    let err = pick(&devs, &by("0000:42:00.0"), &[]).unwrap_err().to_string();
    assert!(err.contains("PCI 0000:42:00.0") && err.contains("no Vulkan device"), "{err}");
    // The environment's VKDIFF_DEVICE takes the same forms; the flag wins over it.
    assert_eq!(pick(&devs, &DeviceChoice::default(), &[("VKDIFF_DEVICE", "41:00.0")]).unwrap(), 2);
    assert_eq!(pick(&devs, &DeviceChoice::index(0), &[("VKDIFF_DEVICE", "41:00.0")]).unwrap(), 0);
    let err = pick(&devs, &DeviceChoice::default(), &[("VKDIFF_DEVICE", "first")]).unwrap_err().to_string();
    assert_eq!(err, "VKDIFF_DEVICE=first: expected an index, a UUID or a PCI address as `vkdiff devices` prints them");
}

#[test]
fn takes_the_gpu_the_scheduler_gave_the_process() {
    let devs = node();
    let auto = DeviceChoice::default();
    // CUDA numbers NVIDIA GPUs in PCI order: 0 is bus 0x41 (Vulkan's device 2).
    assert_eq!(pick(&devs, &auto, &[("CUDA_VISIBLE_DEVICES", "0")]).unwrap(), 2);
    assert_eq!(pick(&devs, &auto, &[("CUDA_VISIBLE_DEVICES", "1,0")]).unwrap(), 1);
    assert_eq!(pick(&devs, &auto, &[("CUDA_VISIBLE_DEVICES", "GPU-6f3c1e2a")]).unwrap(), 1);
    // A Slurm task among several sharing the list takes its own; without a list, its own GPU.
    assert_eq!(pick(&devs, &auto, &[("CUDA_VISIBLE_DEVICES", "0,1"), ("SLURM_LOCALID", "1")]).unwrap(), 1);
    assert_eq!(pick(&devs, &auto, &[("SLURM_LOCALID", "0")]).unwrap(), 2);
    assert_eq!(pick(&devs, &auto, &[("SLURM_LOCALID", "3")]).unwrap(), 1);
    // "-1" or "" (any list that starts invalid) gives the process no NVIDIA GPU, as in CUDA.
    assert_eq!(pick(&devs, &auto, &[("CUDA_VISIBLE_DEVICES", "-1")]).unwrap(), 0);
    assert_eq!(pick(&devs, &auto, &[("CUDA_VISIBLE_DEVICES", "")]).unwrap(), 0);
    // A GPU the list names that Vulkan does not list: the container lacks the driver's ICD.
    let cpu_only = &devs[..1];
    let err = pick(cpu_only, &auto, &[("CUDA_VISIBLE_DEVICES", "0"), ("VK_DRIVER_FILES", "/x/lvp_icd.x86_64.json")])
        .unwrap_err()
        .to_string();
    assert!(
        err.starts_with("CUDA_VISIBLE_DEVICES=0 gives this process NVIDIA GPU 0")
            && err.contains("lists 0 NVIDIA")
            && err.contains("lvp_icd.x86_64.json")
            && err.contains("NVIDIA_DRIVER_CAPABILITIES"),
        "{err}"
    );
    let err = pick(&devs, &auto, &[("ROCR_VISIBLE_DEVICES", "GPU-0123456789abcdef")]).unwrap_err().to_string();
    assert!(err.contains("by index"), "{err}");
}

#[test]
fn require_gpu_refuses_the_cpu_and_names_the_drivers_found() {
    let devs = node();
    let required = DeviceChoice { require_gpu: true, ..DeviceChoice::default() };
    assert_eq!(pick(&devs, &required, &[]).unwrap(), 2);
    let env = [("VK_DRIVER_FILES", "/usr/share/vulkan/icd.d/lvp_icd.x86_64.json")];
    let err = pick(&devs[..1], &required, &env).unwrap_err().to_string();
    assert!(err.contains("`llvmpipe`, is a CPU") && err.contains("found: lvp_icd.x86_64.json"), "{err}");
    let asked_cpu = DeviceChoice { require_gpu: true, ..DeviceChoice::index(0) };
    assert!(matches!(pick(&devs, &asked_cpu, &[]), Err(Error::NoGpu(_))));
    for on in ["1", "yes", "true", "on"] {
        let by_env = [("VKDIFF_REQUIRE_GPU", on)];
        assert!(matches!(pick(&devs[..1], &DeviceChoice::default(), &by_env), Err(Error::NoGpu(_))), "{on}");
    }
    let err = pick(&devs, &DeviceChoice::default(), &[("VKDIFF_REQUIRE_GPU", "2")]).unwrap_err().to_string();
    assert!(err.starts_with("VKDIFF_REQUIRE_GPU=2: expected 1 or 0"), "{err}");
}

#[test]
fn lists_the_driver_manifests_of_the_loaders_search_path() {
    let dir = std::env::temp_dir().join(format!("vkdiff-icds-{}", std::process::id()));
    let icd = dir.join("vulkan/icd.d");
    std::fs::create_dir_all(&icd).unwrap();
    for name in ["nvidia_icd.json", "lvp_icd.x86_64.json", "README"] {
        std::fs::write(icd.join(name), "{}").unwrap();
    }
    let base = dir.display().to_string();
    let env =
        [("XDG_DATA_DIRS", base.as_str()), ("XDG_CONFIG_DIRS", "/nonexistent"), ("XDG_DATA_HOME", "/nonexistent")];
    let found = loader_icds(&env_of(&env));
    std::fs::remove_dir_all(&dir).unwrap();
    // /etc/vulkan/icd.d is always searched; this machine's own manifests may come first.
    assert!(found.ends_with(&["lvp_icd.x86_64.json".to_string(), "nvidia_icd.json".to_string()]), "{found:?}");
    assert_eq!(loader_icds(&env_of(&[("VK_ICD_FILENAMES", "/a/b.json:/c/d.json")])), ["b.json", "d.json"]);
}
