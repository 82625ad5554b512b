//! `vkdiff devices`: every Vulkan device, what it supports and which one vkdiff picks.

use anyhow::Result;
use vkdiff_runtime::{choose, gpu_paths_requested, list_devices, DeviceInfo, GemmFamily};

#[derive(clap::Args)]
pub struct DevicesArgs {
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
}

fn mib(bytes: u64) -> String {
    format!("{} MiB", bytes >> 20)
}

fn describe(d: &DeviceInfo, chosen: bool) -> String {
    let yes = |b: bool| if b { "yes" } else { "no" };
    let sizes = match d.subgroup_size_range {
        Some((lo, hi)) => format!("{} (pinnable {lo}..={hi})", d.subgroup_size),
        None => d.subgroup_size.to_string(),
    };
    let verdict = match d.unsupported_reason() {
        Some(r) => format!("unusable: {r}"),
        None if chosen => "selected (default)".into(),
        None => format!("usable (--device {})", d.index),
    };
    let gpu_paths = gpu_paths_requested();
    let gemm = match (d.gemm_family(gpu_paths), d.gemm_subgroup_width()) {
        (GemmFamily::Subgroup, Some(lanes)) => format!("subgroup-register, {lanes} lanes (CPU)"),
        _ => "shared-memory tiles (GPU)".into(),
    };
    let attention =
        if d.subgroup_attention(gpu_paths) { "subgroup-register (CPU)" } else { "query rows per invocation (GPU)" };
    let paths = if gpu_paths { " (VKDIFF_GPU_PATHS=1: device memory through staging, GPU kernels)" } else { "" };
    [
        format!("[{}] {} — {}", d.index, d.name, verdict),
        format!(
            "    kind: {}, Vulkan {}.{}.{}, driver: {}",
            d.kind.label(),
            d.api_version.0,
            d.api_version.1,
            d.api_version.2,
            d.driver
        ),
        format!(
            "    f16 storage+arith: {}, subgroup size: {sizes}, shuffle: {}, arithmetic: {}, cooperative matrix: {}",
            yes(d.supports_f16()),
            yes(d.subgroup_shuffle),
            yes(d.subgroup_arithmetic),
            yes(d.cooperative_matrix)
        ),
        format!(
            "    device memory: {}, max allocation: {}, max storage binding: {}, shared memory: {} KiB",
            mib(d.device_local_bytes),
            mib(d.max_allocation),
            mib(d.max_storage_buffer_range),
            d.max_shared_memory / 1024
        ),
        format!(
            "    vkdiff uses: storage {}, GEMM/conv kernels: {gemm}, attention: {attention}, timestamps: {}{paths}",
            if d.supports_f16() { "f16 and f32" } else { "f32 only" },
            yes(d.timestamps)
        ),
    ]
    .join("\n")
}

pub fn run(args: &DevicesArgs) -> Result<()> {
    let devices = list_devices()?;
    let chosen = choose(&devices, None).ok();
    if args.json {
        let list: Vec<_> = devices
            .iter()
            .map(|d| {
                serde_json::json!({
                    "index": d.index, "name": d.name, "kind": d.kind.label(), "driver": d.driver,
                    "vulkan": format!("{}.{}.{}", d.api_version.0, d.api_version.1, d.api_version.2),
                    "f16": d.supports_f16(), "subgroup_size": d.subgroup_size,
                    "subgroup_size_range": d.subgroup_size_range,
                    "cooperative_matrix": d.cooperative_matrix, "device_memory_bytes": d.device_local_bytes,
                    "max_storage_buffer_range": d.max_storage_buffer_range, "usable": d.unsupported_reason().is_none(),
                    "unusable_reason": d.unsupported_reason(), "selected": chosen == Some(d.index),
                })
            })
            .collect();
        println!("{}", serde_json::to_string_pretty(&list)?);
        return Ok(());
    }
    if devices.is_empty() {
        anyhow::bail!("no Vulkan device found; install a driver (mesa-vulkan-drivers gives the CPU device lavapipe)");
    }
    for d in &devices {
        println!("{}", describe(d, chosen == Some(d.index)));
    }
    Ok(())
}
