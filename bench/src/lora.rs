//! `vkdiff bench lora`: merging a rank-r kohya LoRA over SDXL base's 722 transformer linears
//! (random weights) on the device, restoring, and re-merging, beside the same merge arithmetic
//! in torch on this machine's CPU in the same run.

use anyhow::Result;
use std::time::Instant;
use vkdiff_lora::{LoraFile, LoraMerger, Targets};
use vkdiff_networks::{Checkpoint, UNet, UNetConfig};
use vkdiff_runtime::Environment;

const REFERENCE: crate::cpu_reference::Script = crate::cpu_reference::script!("lora_merge_cpu_reference.py");

#[derive(clap::Args)]
pub struct LoraArgs {
    #[command(flatten)]
    device: vkdiff_args::DeviceArgs,
    /// The random LoRA's rank.
    #[arg(long, default_value_t = 32)]
    rank: usize,
    /// f16 (f32 arithmetic, matrix units where the GPU has them) or f32.
    #[arg(long, value_enum, default_value_t = vkdiff_args::Precision::F16)]
    precision: vkdiff_args::Precision,
    /// Skip torch on the CPU (needs python with torch: $VKDIFF_REFERENCE_PYTHON or python3).
    #[arg(long)]
    no_cpu_reference: bool,
}

pub fn run(args: &LoraArgs, env: &Environment) -> Result<()> {
    let dtype = args.precision.dtype();
    let ctx = args.device.open(env)?;
    let unet = UNet::load(&UNetConfig::sdxl_base(), &Checkpoint::random(&ctx, dtype, 0))?;
    let shapes = transformer_linears(&unet);
    let path = std::env::temp_dir().join(format!("vkdiff-bench-lora-{}.safetensors", std::process::id()));
    write_lora(&path, &shapes, args.rank, 0)?;
    let lora = LoraFile::open(&path);
    std::fs::remove_file(&path)?;
    let lora = lora?;
    let targets = Targets::unet_only(&unet);
    let mut merger = LoraMerger::new();
    let start = Instant::now();
    let first = merger.apply(&targets, &[(&lora, 0.8)])?;
    let first_s = start.elapsed().as_secs_f64();
    let again = merger.apply(&targets, &[(&lora, 0.5)])?;
    let start = Instant::now();
    merger.restore()?;
    let restore_s = start.elapsed().as_secs_f64();
    let params: usize = shapes.iter().map(|(_, [o, i])| o * i).sum();
    println!(
        "{} | rank-{} LoRA on {} SDXL UNet linears ({:.2} G weights, {}): first merge {:.2} s (with host backups), \
            merge {:.2} s, restore {:.2} s",
        ctx.info().name,
        args.rank,
        first.weights,
        params as f64 / 1e9,
        crate::kernels::dtype_name(dtype),
        first_s,
        again.seconds,
        restore_s
    );
    if !args.no_cpu_reference {
        match reference(env, &shapes, args.rank) {
            Ok(cpu) => println!("torch CPU f32 merge: {cpu:.2} s | merge speed-up {:.2}×", cpu / again.seconds),
            Err(why) => println!("torch CPU reference unavailable: {why}"),
        }
    }
    Ok(())
}

/// The Linear weights inside the UNet's transformers (kohya's SDXL LoRA targets) and their shapes.
pub(super) fn transformer_linears(unet: &UNet) -> Vec<(String, [usize; 2])> {
    let params = unet.parameters();
    params
        .names()
        .into_iter()
        .filter(|n| n.contains(".attentions.") && n.ends_with(".weight"))
        .filter_map(|n| match params.get(n)?.torch_shape[..] {
            [o, i] => Some((n.to_string(), [o, i])),
            _ => None,
        })
        .collect()
}

/// A kohya file in diffusers module names: small random factors, alpha 16.
pub(super) fn write_lora(path: &std::path::Path, shapes: &[(String, [usize; 2])], r: usize, seed: u64) -> Result<()> {
    let mut state = 0x2545_f491_4f6c_dd1du64 ^ seed.wrapping_mul(0x9e37_79b9_7f4a_7c15);
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        ((state >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * 0.02
    };
    let mut tensors: Vec<(String, Vec<usize>, Vec<f32>)> = Vec::new();
    for (name, [o, i]) in shapes {
        let key = format!("lora_unet_{}", name.trim_end_matches(".weight").replace('.', "_"));
        tensors.push((format!("{key}.lora_down.weight"), vec![r, *i], (0..r * i).map(|_| next()).collect()));
        tensors.push((format!("{key}.lora_up.weight"), vec![*o, r], (0..o * r).map(|_| next()).collect()));
        tensors.push((format!("{key}.alpha"), vec![], vec![16.0]));
    }
    let refs: Vec<(&str, &[usize], &[f32])> =
        tensors.iter().map(|(n, s, v)| (n.as_str(), s.as_slice(), v.as_slice())).collect();
    Ok(vkdiff_formats::write_safetensors_f32(path, &refs, &Default::default())?)
}

fn reference(env: &Environment, shapes: &[(String, [usize; 2])], rank: usize) -> std::result::Result<f64, String> {
    let job = serde_json::json!({ "rank": rank, "shapes": shapes.iter().map(|(_, s)| s).collect::<Vec<_>>() });
    let out: MergeTime =
        crate::cpu_reference::run_python_reference(env, REFERENCE, [] as [&str; 0], Some(&job.to_string()))?;
    Ok(out.merge_s)
}

/// What `tools/lora_merge_cpu_reference.py` prints (and more, unread).
#[derive(serde::Deserialize)]
struct MergeTime {
    merge_s: f64,
}
