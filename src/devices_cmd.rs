//! `vkdiff devices`: every Vulkan device, what it supports and which one vkdiff picks.

use anyhow::Result;
use vkdiff_runtime::{
    built_cooperative_variants, choose, gpu_paths_requested, list_devices, requested_fragment, CooperativeSetting,
    DeviceInfo, GemmFamily, COOPERATIVE_MATRIX2_FEATURES,
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
    let gemm = match (d.gemm_family(gpu_paths), d.gemm_subgroup_width(), d.cooperative_variant()) {
        (GemmFamily::Subgroup, Some(lanes), _) => format!("subgroup-register, {lanes} lanes (CPU)"),
        (GemmFamily::Cooperative, _, Some(f)) => {
            let tried = match CooperativeSetting::from_env() {
                Ok(CooperativeSetting::Trial) => {
                    ", unless a product timed on them as vkdiff starts differs from the tiled kernels' or takes over \
                     1.25× their time"
                }
                _ => "",
            };
            format!(
                "matrix units, {} f16→f32 fragments, {} lanes{tried} (f32 products: shared-memory tiles)",
                f.shape(),
                f.lanes
            )
        }
        _ => "shared-memory tiles (GPU)".into(),
    };
    let tiles = if d.holds_tiled_attention() { "register-blocked tiles for heads up to 64, else " } else { "" };
    let flash = if d.subgroup_attention(gpu_paths) {
        "subgroup-register (CPU)".to_string()
    } else if d.gemm_family(gpu_paths) == GemmFamily::Cooperative {
        format!("matrix units for f16 heads up to 64, else {tiles}query rows per invocation (GPU)")
    } else {
        format!("{tiles}query rows per invocation (GPU)")
    };
    let attention = format!(
        "{flash}; heads over 128 (the VAE's): products around a row softmax, f16 heads widened to f32 for them"
    );
    let wider = if d.lavapipe_mesa.is_some() && vkdiff_runtime::wider_lavapipe_vectors_available() {
        " (this CPU has AVX-512: LP_NATIVE_VECTOR_WIDTH=512 runs 16-lane kernels, which compile 2–3× slower and ran \
            the UNet 1.04× faster on an AMD EPYC, 4.9× slower on an Intel Xeon)"
    } else {
        ""
    };
    let compile = match (d.lavapipe_mesa, d.quick_compile(gpu_paths)) {
        (Some(_), true) => ", kernels compiled at first use, small products on the quickly compiled variants",
        (Some(_), false) => ", kernels compiled at first use",
        (None, _) => "",
    };
    let paths = if gpu_paths { " (VKDIFF_GPU_PATHS=1: device memory through staging, GPU kernels)" } else { "" };
    [
        format!("[{}] {}{wider} — {}", d.index, d.name, verdict),
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
            "    vkdiff uses: storage {}, GEMM/conv kernels: {gemm}, attention: {attention}, timestamps: {}{compile}{paths}",
            if d.supports_f16() { "f16 and f32" } else { "f32 only" },
            yes(d.timestamps())
        ),
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

pub fn run(args: &DevicesArgs) -> Result<()> {
    // A malformed request would otherwise show as the device's default choice.
    requested_fragment()?;
    CooperativeSetting::from_env()?;
    vkdiff_runtime::MatrixTile::from_env()?;
    vkdiff_runtime::ProbeChoice::attention_from_env()?;
    vkdiff_runtime::ProbeChoice::linear_from_env()?;
    vkdiff_runtime::ProbeChoice::conv_from_env()?;
    vkdiff_runtime::tuning_from_env()?;
    if args.compile {
        let request = crate::devices_compile::CompileRequest {
            choice: args.device.choice(),
            kernels: &args.kernel,
            no_spills: args.no_spills,
            json: args.json,
        };
        return crate::devices_compile::run(&request);
    }
    let devices = list_devices()?;
    let chosen = choose(&devices, &Default::default()).ok();
    if args.json {
        let gpu_paths = gpu_paths_requested();
        // The Vulkan instance is created at this version (VKDIFF_VULKAN_API caps it).
        let (major, minor) = vkdiff_runtime::api_limit()?;
        let list: Vec<_> = devices
            .iter()
            .map(|d| {
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
                    "unusable_reason": d.unsupported_reason(), "selected": chosen == Some(d.index), "quick_compile": d.quick_compile(gpu_paths),
                    "uuid": d.uuid_text(), "pci": d.pci.map(|p| p.to_string()),
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
        println!("{}", describe(d, chosen == Some(d.index)));
    }
    let icds = vkdiff_runtime::loader_icds(&|name| std::env::var(name).ok());
    println!("Vulkan driver manifests the loader reads: {}", icds.join(", "));
    Ok(())
}
