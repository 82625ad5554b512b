//! `vkdiff devices`: every Vulkan device, what it supports and which one vkdiff picks.

use anyhow::Result;
use vkdiff_runtime::{
    built_cooperative_variants, choose, list_devices, DeviceInfo, Environment, KernelPlan, Settings,
    COOPERATIVE_MATRIX2_FEATURES,
};

#[derive(clap::Args)]
pub struct DevicesArgs {
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
    /// Compile every kernel variant the chosen device can run, and print what its driver
    /// reports of each (registers, spills, instruction counts, where it reports them).
    #[arg(long)]
    compile: bool,
    /// With --compile: only these kernels (comma-separated names, as --compile prints them).
    #[arg(long, value_delimiter = ',', requires = "compile")]
    kernel: Vec<String>,
    /// With --compile: fail where a kernel variant spills registers to memory.
    #[arg(long, requires = "compile")]
    no_spills: bool,
    #[command(flatten)]
    device: vkdiff_args::DeviceArgs,
}

fn mib(bytes: u64) -> String {
    format!("{} MiB", bytes >> 20)
}

fn describe(d: &DeviceInfo, chosen: bool, settings: &Settings) -> String {
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
    let plan = KernelPlan::for_device(d, settings).to_string().replace('\n', "\n      ");
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
            "    UUID: {}, PCI: {}, compute queue family: {}",
            d.uuid_text(),
            d.pci.map_or("unknown (no VK_EXT_pci_bus_info)".into(), |p| p.to_string()),
            d.compute_queue_family.map_or("none".into(), |f| f.to_string())
        ),
        format!(
            "    f16 storage+arith: {}, subgroup size: {sizes}, shuffle: {}, arithmetic: {}",
            yes(d.supports_f16()),
            yes(d.subgroup_shuffle),
            yes(d.subgroup_arithmetic),
        ),
        format!("    cooperative matrix: {}", matrix_units(d)),
        format!(
            "    device memory: {}, max allocation: {}, max storage binding: {}, shared memory: {} KiB",
            mib(d.device_local_bytes),
            mib(d.max_allocation),
            mib(d.max_storage_buffer_range),
            d.max_shared_memory / 1024
        ),
        format!(
            "    vkdiff uses: storage {}, timestamps: {}",
            if d.supports_f16() { "f16 and f32" } else { "f32 only" },
            yes(d.timestamps())
        ),
        format!("      {plan}"),
    ]
    .join("\n")
}

/// The shapes the device's matrix units list, and whether a cooperative variant fits them.
fn matrix_units(d: &DeviceInfo) -> String {
    if d.matrix_shapes.is_empty() {
        return "no (VK_KHR_cooperative_matrix not offered)".into();
    }
    let shapes: Vec<String> = d.matrix_shapes.iter().map(|s| s.label()).collect();
    let flexible: Vec<String> = d.flexible_shapes.iter().map(|s| s.label()).collect();
    let flexible = if flexible.is_empty() {
        String::new()
    } else {
        format!("; flexible dimensions (VK_NV_cooperative_matrix2) in multiples of {}", flexible.join(", "))
    };
    let verdict = match d.cooperative_variant() {
        Some(f) if f.flexible => {
            format!("vkdiff's {} variant at {} lanes runs through flexible dimensions", f.shape(), f.lanes)
        }
        Some(f) => format!("vkdiff's {} variant at {} lanes fits", f.shape(), f.lanes),
        None if !d.cooperative_features => "not usable: no cooperativeMatrix or vulkanMemoryModel feature".into(),
        None => format!(
            "no vkdiff variant fits them (f16·f16+f32 at subgroup scope, {}): f16 products take the tiled kernels",
            built_cooperative_variants()
        ),
    };
    format!("{}{flexible}{}; {verdict}", shapes.join(", "), matrix2_features(d))
}

/// "; VK_NV_cooperative_matrix2 features: …" where the device reports any: what a kernel on
/// that extension's workgroup-scope matrices or tensor loads could count on.
fn matrix2_features(d: &DeviceInfo) -> String {
    if d.cooperative_matrix2.is_empty() {
        return String::new();
    }
    let missing: Vec<&str> =
        COOPERATIVE_MATRIX2_FEATURES.iter().copied().filter(|f| !d.cooperative_matrix2.contains(f)).collect();
    let missing = if missing.is_empty() { String::new() } else { format!(" (not {})", missing.join(", ")) };
    let tiles: Vec<String> = d.matrix2_tiles().iter().map(|t| t.label()).collect();
    let probe = match tiles.is_empty() {
        true => String::new(),
        false => format!("; its probes (bench kernels) run {}", tiles.join(", ")),
    };
    format!("; VK_NV_cooperative_matrix2 features: {}{missing}{probe}", d.cooperative_matrix2.join(", "))
}

pub fn run(args: &DevicesArgs, env: &Environment) -> Result<()> {
    // A malformed setting would otherwise show as the device's default choice.
    let settings = Settings::from_environment(env)?;
    let choice = args.device.choice(env)?;
    if args.compile {
        let request = crate::devices_compile::CompileRequest {
            choice,
            settings,
            kernels: &args.kernel,
            no_spills: args.no_spills,
            json: args.json,
        };
        return crate::devices_compile::run(&request);
    }
    let devices = list_devices(&settings, env)?;
    let chosen = choose(&devices, &choice).ok();
    if args.json {
        let (major, minor) = settings.vulkan_api;
        let list: Vec<_> = devices
            .iter()
            .map(|d| {
                let plan = KernelPlan::for_device(d, &settings);
                serde_json::json!({
                    "index": d.index, "name": d.name, "kind": d.kind.label(), "driver": d.driver,
                    "vulkan": format!("{}.{}.{}", d.api_version.0, d.api_version.1, d.api_version.2),
                    "instance_vulkan": format!("{major}.{minor}"),
                    "f16": d.supports_f16(), "subgroup_size": d.subgroup_size,
                    "subgroup_size_range": d.subgroup_size_range,
                    "cooperative_matrix_shapes": d.matrix_shapes.iter().map(|s| s.label()).collect::<Vec<_>>(),
                    "cooperative_matrix2_features": d.cooperative_matrix2,
                    "cooperative_matrix2_probe_tiles": d.matrix2_tiles().iter().map(|t| t.label()).collect::<Vec<_>>(),
                    "cooperative_variant": d.cooperative_variant().map(|f| serde_json::json!({
                        "m": f.m, "n": f.n, "k": f.k, "lanes": f.lanes, "flexible_dimensions": f.flexible })), "device_memory_bytes": d.device_local_bytes,
                    "max_storage_buffer_range": d.max_storage_buffer_range, "usable": d.unsupported_reason().is_none(),
                    "unusable_reason": d.unsupported_reason(), "selected": chosen == Some(d.index), "quick_compile": plan.quick_compile,
                    "uuid": d.uuid_text(), "pci": d.pci.map(|p| p.to_string()),
                    "kernels": { "gemm": format!("{:?}", plan.gemm).to_lowercase(), "matrix_unit_trial": plan.trial,
                        "matrix_tile": plan.tile.name(), "subgroup_attention": plan.subgroup_attention, "plan": plan.to_string() },
                })
            })
            .collect();
        println!("{}", serde_json::to_string_pretty(&list)?);
        return Ok(());
    }
    if devices.is_empty() {
        return Err(vkdiff_runtime::Error::NoDevice.into());
    }
    for d in &devices {
        println!("{}", describe(d, chosen == Some(d.index), &settings));
    }
    println!("Vulkan driver manifests the loader reads: {}", vkdiff_runtime::loader_icds(env).join(", "));
    Ok(())
}
