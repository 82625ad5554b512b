//! `vkdiff devices --compile`: every kernel variant the chosen device can pick, compiled by its
//! driver, with what the driver reports of each (see `vkdiff_runtime::selectable_variants`).

use anyhow::{bail, Result};
use vkdiff_runtime::{
    describe_statistics, selectable_variants, variant_label, CompiledKernel, Context, DeviceChoice, Settings,
    StatisticValue,
};

/// What `--compile` was asked for.
pub struct CompileRequest<'a> {
    pub choice: DeviceChoice,
    pub settings: Settings,
    /// Only these kernels (by name); all where empty.
    pub kernels: &'a [String],
    /// Fail where a variant spills registers to memory.
    pub no_spills: bool,
    pub json: bool,
}

pub fn run(request: &CompileRequest) -> Result<()> {
    let ctx = Context::for_census(&request.choice, request.settings)?;
    let info = ctx.info();
    let mut variants = selectable_variants(info, &request.settings);
    let known: Vec<&str> = variants.iter().map(|v| v.kernel).collect();
    if let Some(unknown) = request.kernels.iter().find(|k| !known.contains(&k.as_str())) {
        return Err(vkdiff_args::Usage(format!(
            "--kernel {unknown}: `{}` runs no kernel of that name (it runs: {})",
            info.name,
            distinct(&known).join(", ")
        ))
        .into());
    }
    if !request.kernels.is_empty() {
        variants.retain(|v| request.kernels.iter().any(|k| k == v.kernel));
    }
    if !request.json {
        println!("Compiling the {} kernel variants `{}` can run ({}):", variants.len(), info.name, info.driver);
    }
    let (mut compiled, mut failed) = (Vec::new(), Vec::new());
    for &variant in &variants {
        match ctx.compile_for_census(variant) {
            Ok(k) => {
                if !request.json {
                    println!("  {}", line(&k));
                }
                compiled.push(k);
            }
            Err(e) => {
                if !request.json {
                    println!("  {}: FAILED: {e}", variant_label(variant));
                }
                failed.push(format!("{}: {e}", variant_label(variant)));
            }
        }
    }
    let spilling: Vec<&CompiledKernel> = compiled.iter().filter(|k| k.memory_spills().is_some_and(|b| b > 0)).collect();
    if request.json {
        let each: Vec<_> = compiled.iter().map(json).collect();
        let out = serde_json::json!({ "device": info.name, "driver": info.driver, "compiled": each, "failed": failed });
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        println!("{}", summary(&compiled, &spilling));
    }
    if !failed.is_empty() {
        bail!(
            "{} of {} kernel variants failed to compile on `{}`: {}",
            failed.len(),
            variants.len(),
            info.name,
            failed[0]
        );
    }
    if request.no_spills && !spilling.is_empty() {
        let names: Vec<String> = spilling.iter().map(|k| variant_label(k.variant)).collect();
        bail!(
            "--no-spills: {} kernel variants spill registers to memory on `{}`: {}",
            names.len(),
            info.name,
            names.join("; ")
        );
    }
    Ok(())
}

fn distinct<'a>(names: &[&'a str]) -> Vec<&'a str> {
    let mut out: Vec<&str> = names.to_vec();
    out.dedup();
    out
}

/// "gemm_coop F16 FM=16 … 0.041 s: VGPRs 168, …" (each executable's statistics after `;`).
fn line(k: &CompiledKernel) -> String {
    let stats: Vec<String> = k.statistics.iter().map(describe_statistics).collect();
    let stats = if stats.is_empty() { String::new() } else { format!(": {}", stats.join("; ")) };
    format!("{} {:.3} s{stats}", variant_label(k.variant), k.seconds)
}

fn summary(compiled: &[CompiledKernel], spilling: &[&CompiledKernel]) -> String {
    let seconds: f64 = compiled.iter().map(|k| k.seconds).sum();
    let spills = if compiled.iter().all(|k| k.memory_spills().is_none()) {
        "the driver reports no spill figure".to_string()
    } else if spilling.is_empty() {
        "none spills registers to memory".to_string()
    } else {
        let names: Vec<String> = spilling
            .iter()
            .map(|k| format!("{} ({} bytes of scratch)", variant_label(k.variant), k.memory_spills().unwrap_or(0)))
            .collect();
        format!("{} spill registers to memory: {}", spilling.len(), names.join("; "))
    };
    format!("{} kernel variants compiled in {seconds:.2} s; {spills}", compiled.len())
}

fn json(k: &CompiledKernel) -> serde_json::Value {
    let value = |v: &StatisticValue| match *v {
        StatisticValue::Bool(b) => serde_json::json!(b),
        StatisticValue::Int(i) => serde_json::json!(i),
        StatisticValue::Uint(u) => serde_json::json!(u),
        StatisticValue::Float(x) => serde_json::json!(x),
        StatisticValue::Unknown => serde_json::Value::Null,
    };
    let executables: Vec<serde_json::Map<String, serde_json::Value>> =
        k.statistics.iter().map(|s| s.iter().map(|(n, v)| (n.clone(), value(v))).collect()).collect();
    serde_json::json!({
        "kernel": k.variant.kernel,
        "dtype": format!("{:?}", k.variant.dtype).to_lowercase(),
        "params": k.variant.params.iter().map(|(n, v)| (n.to_string(), serde_json::json!(v))).collect::<serde_json::Map<_, _>>(),
        "seconds": k.seconds,
        "statistics": executables,
        "memory_spills": k.memory_spills(),
    })
}
