//! The VAE decode's memory plan on a CPU device (lavapipe: Mesa 22.3 in the suite, 26.1 in its
//! CI pass), held against SDXL's full-size VAE by its config alone (no weights): the room is
//! the host's available memory, not the heap the driver reports (Mesa 22.3: 2 GiB, which had
//! refused a 512² decode with "0 MiB free"), so a 512² decode plans whole and a decode too large
//! for the host is tiled or refused by the host's figure.

use vkdiff_networks::{VaeConfig, SDXL_VAE_CONFIG};
use vkdiff_pipeline::{VaePlan, VaeTilingSetting};
use vkdiff_runtime::{Context, DeviceKind, Dtype, MemoryRoom, HOST_MEMORY};

/// /proc/meminfo's MemAvailable, read here independently of the runtime.
fn mem_available() -> u64 {
    let text = std::fs::read_to_string("/proc/meminfo").unwrap();
    let line = text.lines().find(|l| l.starts_with("MemAvailable:")).unwrap();
    line.split_whitespace().nth(1).unwrap().parse::<u64>().unwrap() * 1024
}

#[test]
fn a_cpu_device_plans_the_full_size_vae_with_the_hosts_memory() {
    let ctx = Context::new(&Default::default(), vkdiff_testkit::settings())
        .expect("a Vulkan device (apt-get install mesa-vulkan-drivers)");
    assert_eq!(ctx.info().kind, DeviceKind::Cpu, "these tests run on lavapipe");
    let room = ctx.memory_room();
    assert_eq!(room.source, HOST_MEMORY);
    let available = mem_available();
    assert!(
        room.free.abs_diff(available) < available / 4,
        "room {} MiB, the host's available memory {} MiB",
        room.free >> 20,
        available >> 20
    );
    assert!(available > 4 << 30, "the test needs a host with 4 GiB available, this one has {} MiB", available >> 20);

    let config: VaeConfig = serde_json::from_str(SDXL_VAE_CONFIG).unwrap();
    let max_allocation = ctx.info().max_allocation;
    let plan = |room: MemoryRoom, side: usize| {
        VaePlan::choose(&config, Dtype::F32, room, max_allocation, VaeTilingSetting::Auto, 1, side, side)
    };
    // 512²: 1,831 MiB of activations and 160 of Winograd's scratch (2 × (16 MiB of filters + 2 ×
    // 32 MiB of planes)), whole on this host (the heap alone had refused it).
    let at_512 = plan(room, 512).unwrap();
    assert!(at_512.tiling.is_none() && (1990..=1991).contains(&(at_512.whole_bytes >> 20)), "{at_512:?}");
    // A host of 4 GiB with 1 GiB left tiles the same decode, naming its figure's source.
    let small = MemoryRoom { free: 1 << 30, budget: 4 << 30, source: HOST_MEMORY };
    let tiled = plan(small, 512).unwrap();
    assert!(tiled.tiling.is_some() && tiled.planned_bytes < 1 << 30, "{tiled:?}");
    let note = tiled.note(512, 512).unwrap();
    assert!(note.contains("1024 MiB free by the host's available memory"), "{note}");
    // And with too little for any tile, one line before any step.
    let none = MemoryRoom { free: 64 << 20, budget: 24 << 30, source: HOST_MEMORY };
    let refused = plan(none, 1024).unwrap_err().to_string();
    assert!(refused.contains("free by the host's available memory"), "{refused}");
}
