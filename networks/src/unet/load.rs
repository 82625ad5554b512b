//! Where a UNet's config and weights come from: a diffusers folder, or an original single file
//! whose config is read back from its tensor shapes.

use crate::error::{Error, Result};
use crate::unet::config::UNetConfig;
use crate::unet::single_file::{infer_unet_config, unet_names};
use crate::weights::{component_folder, Checkpoint};
use std::collections::HashMap;
use std::path::Path;
use vkdiff_formats::{SafeTensors, TorchPth};
use vkdiff_runtime::{Context, Dtype};

/// Prefix of the UNet's tensors in an original (sgm / ComfyUI / A1111) single-file checkpoint.
const SINGLE_FILE_UNET: &str = "model.diffusion_model.";

/// A UNet from `path`: a diffusers model folder (holding `unet/` or being it, with
/// `config.json` and `diffusion_pytorch_model[.fp16].safetensors`, sharded or not) or an
/// original single-file checkpoint, whose config is inferred from tensor shapes.
pub fn unet_checkpoint(ctx: &Context, path: &Path, dtype: Dtype) -> Result<(UNetConfig, Checkpoint)> {
    if path.is_dir() {
        let dir = component_folder(path, "unet")?;
        let config = UNetConfig::from_file(&dir.join("config.json"))?;
        return Ok((config, Checkpoint::diffusers(ctx, &dir, "diffusion_pytorch_model", dtype)?));
    }
    let file = SafeTensors::open(path)?;
    let config = single_file_unet_config(&file)?;
    single_file_unet(ctx, file, config, dtype)
}

/// A UNet swapped in for a model's (SDXL-Lightning's, DMD2's): a diffusers UNet folder (or model
/// folder) with its own config, or one file of weights for the architecture of `base`, as
/// diffusers' `UNet2DConditionModel.from_config(base).load_state_dict(file)`, stored under
/// diffusers' names or the original ones (with or without `model.diffusion_model.`), as
/// safetensors or a torch `.bin`/`.pth`/`.pt`/`.ckpt` state dict.
pub fn swapped_unet_checkpoint(
    ctx: &Context,
    path: &Path,
    base: &UNetConfig,
    dtype: Dtype,
) -> Result<(UNetConfig, Checkpoint)> {
    if path.is_dir() {
        return unet_checkpoint(ctx, path, dtype);
    }
    let file = open_weights(path)?;
    let config = base.clone();
    match unet_file_layout(&file)? {
        UNetLayout::Diffusers => Ok((config, Checkpoint::diffusers_file(ctx, file, dtype))),
        UNetLayout::Original { prefix } => {
            let names = unet_names(&config)?;
            Ok((config, Checkpoint::single_file_part(ctx, file, prefix, Some(names), dtype)))
        }
    }
}

/// What can be checked of a swapped UNet without reading its weights: a folder's config, a
/// safetensors file's header and layout (a torch pickle is read whole, so only as it loads).
pub fn check_swapped_unet(path: &Path) -> Result<()> {
    if path.is_dir() {
        return read_unet_config(path).map(drop);
    }
    match path.extension().and_then(|e| e.to_str()) {
        Some("safetensors") => unet_file_layout(&SafeTensors::open(path)?).map(drop),
        _ => Ok(()),
    }
}

/// The UNet config a swapped UNet at `path` runs with: its folder's, else `base`.
pub fn swapped_unet_config(path: &Path, base: &UNetConfig) -> Result<UNetConfig> {
    if path.is_dir() {
        return read_unet_config(path);
    }
    Ok(base.clone())
}

/// A weights file: safetensors, or a torch pickle converted in memory.
fn open_weights(path: &Path) -> Result<SafeTensors> {
    let pickled = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| ["bin", "pth", "pt", "ckpt"].contains(&e.to_ascii_lowercase().as_str()));
    Ok(if pickled { TorchPth::open(path)?.to_safetensors()? } else { SafeTensors::open(path)? })
}

enum UNetLayout {
    Diffusers,
    Original { prefix: &'static str },
}

/// How a UNet file names its tensors, from the names of its input convolution.
fn unet_file_layout(file: &SafeTensors) -> Result<UNetLayout> {
    let has = |name: &str| file.entries.contains_key(name);
    if has("conv_in.weight") {
        Ok(UNetLayout::Diffusers)
    } else if has(&format!("{SINGLE_FILE_UNET}input_blocks.0.0.weight")) {
        Ok(UNetLayout::Original { prefix: SINGLE_FILE_UNET })
    } else if has("input_blocks.0.0.weight") {
        Ok(UNetLayout::Original { prefix: "" })
    } else {
        Err(Error::Checkpoint(format!(
            "{}: no UNet here (no `conv_in.weight` of diffusers' names, nor `input_blocks.0.0.weight` of the original \
                ones, with or without `{SINGLE_FILE_UNET}`)",
            file.path.display()
        )))
    }
}

/// The config of the UNet at `path` (as [`unet_checkpoint`] reads it), without its weights.
pub fn read_unet_config(path: &Path) -> Result<UNetConfig> {
    if path.is_dir() {
        return UNetConfig::from_file(&component_folder(path, "unet")?.join("config.json"));
    }
    single_file_unet_config(&SafeTensors::open(path)?)
}

/// A single-file UNet with a config given by the caller (for models whose head counts or norm
/// groups differ from SDXL's conventions, which shapes cannot tell).
pub fn single_file_unet_checkpoint(
    ctx: &Context,
    path: &Path,
    config: UNetConfig,
    dtype: Dtype,
) -> Result<(UNetConfig, Checkpoint)> {
    config.validate()?;
    single_file_unet(ctx, SafeTensors::open(path)?, config, dtype)
}

fn single_file_unet(
    ctx: &Context,
    file: SafeTensors,
    config: UNetConfig,
    dtype: Dtype,
) -> Result<(UNetConfig, Checkpoint)> {
    let names = unet_names(&config)?;
    Ok((config, Checkpoint::single_file_part(ctx, file, SINGLE_FILE_UNET, Some(names), dtype)))
}

/// A single file's UNet config, inferred from its tensor shapes.
fn single_file_unet_config(file: &SafeTensors) -> Result<UNetConfig> {
    if !file.entries.keys().any(|k| k.starts_with(SINGLE_FILE_UNET)) {
        return Err(Error::Checkpoint(format!(
            "{}: no `{SINGLE_FILE_UNET}*` tensors; not an original-layout SDXL checkpoint (for a diffusers model pass \
                its folder)",
            file.path.display()
        )));
    }
    let shapes: HashMap<&str, &[usize]> = file
        .entries
        .iter()
        .filter_map(|(k, e)| Some((k.strip_prefix(SINGLE_FILE_UNET)?, e.shape.as_slice())))
        .collect();
    infer_unet_config(&shapes).map_err(|e| Error::Checkpoint(format!("{}: {e}", file.path.display())))
}
