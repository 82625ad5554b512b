//! LoRA files: kohya / sd-scripts (`lora_unet_…​.lora_down.weight`), diffusers / PEFT
//! (`unet.….lora_A.weight`, with or without `base_model.model.`, CLIP-L with or without
//! `text_model.`, and the older `to_q_lora.down.weight` spellings), and ComfyUI's own
//! (`diffusion_model.<original path>`, `text_encoders.clip_l.transformer.…`), read into one list
//! of modules, each a pair of factors with its scale (reference/sdxl.md §8.1–8.2).

use crate::component::Component;
use crate::error::{Error, Result};
use crate::metadata::PeftConfigs;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use vkdiff_formats::Error as FileError;
use vkdiff_formats::SafeTensors;

/// How a module names the weight it adapts.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Address {
    /// A kohya name after its prefix: a module path with `.` turned into `_` (ambiguous, so it is
    /// looked up in a dictionary built from the network's own names, never parsed).
    Kohya(String),
    /// A dotted diffusers / transformers module path (`down_blocks.1.attentions.0.proj_in`).
    Path(String),
}

/// One adapted layer: ΔW = scale · up · down, with up [out, r(, 1, 1)] and down [r, in(, kh, kw)].
#[derive(Clone, Debug)]
pub struct Module {
    /// The module's name in the file, for messages.
    pub key: String,
    pub component: Component,
    pub address: Address,
    pub down_shape: Vec<usize>,
    pub up_shape: Vec<usize>,
    /// alpha / r (alpha / √r under rsLoRA); 1 where the file stores no alpha.
    pub scale: f32,
    down: String,
    up: String,
}

impl Module {
    pub fn rank(&self) -> usize {
        self.down_shape[0]
    }

    /// The PyTorch shape of the delta: [out, in] or [out, in, kh, kw].
    pub fn delta_shape(&self) -> Vec<usize> {
        let mut s = vec![self.up_shape[0]];
        s.extend(&self.down_shape[1..]);
        s
    }
}

/// An open LoRA file and its modules, sorted by key. Factor values are read on demand.
pub struct LoraFile {
    pub path: PathBuf,
    pub modules: Vec<Module>,
    file: SafeTensors,
}

#[derive(Clone, Copy, PartialEq)]
enum Role {
    Down,
    Up,
    Alpha,
}

#[derive(Default)]
struct Parts {
    down: Option<String>,
    up: Option<String>,
    alpha: Option<String>,
}

const KOHYA: [(&str, Component); 4] = [
    ("lora_unet_", Component::Unet),
    ("lora_te1_", Component::TextEncoder1),
    ("lora_te2_", Component::TextEncoder2),
    ("lora_te_", Component::TextEncoder1),
];
const DIFFUSERS: [(&str, Component); 5] = [
    ("unet.", Component::Unet),
    ("text_encoder.", Component::TextEncoder1),
    ("text_encoder_2.", Component::TextEncoder2),
    // ComfyUI's LoRA save node and its loader's generic format.
    ("text_encoders.clip_l.transformer.", Component::TextEncoder1),
    ("text_encoders.clip_g.transformer.", Component::TextEncoder2),
];
/// ComfyUI's UNet prefix, followed by the original (sgm) module path.
const COMFY_UNET: &str = "diffusion_model.";
/// PEFT's wrapper levels, in front of the module path of a saved `PeftModel`.
const PEFT_WRAPPER: &str = "base_model.model.";
/// Top-level modules of a diffusers UNet: UNet keys ComfyUI and older diffusers files write
/// without `unet.`.
const UNET_MODULES: [&str; 8] = [
    "down_blocks.",
    "mid_block.",
    "up_blocks.",
    "conv_in.",
    "conv_out.",
    "conv_norm_out.",
    "time_embedding.",
    "add_embedding.",
];

impl LoraFile {
    pub fn open(path: &Path) -> Result<LoraFile> {
        let file = SafeTensors::open(path)?;
        let peft = PeftConfigs::read(path)?;
        let bad = |why: String| Error::from(FileError::Format { path: path.to_path_buf(), why });
        let mut grouped: BTreeMap<(Component, String), (Address, Parts)> = BTreeMap::new();
        for key in file.entries.keys() {
            let (component, address, module_key, role) = classify(key).map_err(|what| Error::Unsupported {
                path: path.to_path_buf(),
                key: key.clone(),
                what,
            })?;
            let parts = &mut grouped.entry((component, module_key)).or_insert_with(|| (address, Parts::default())).1;
            let slot = match role {
                Role::Down => &mut parts.down,
                Role::Up => &mut parts.up,
                Role::Alpha => &mut parts.alpha,
            };
            if let Some(other) = slot.replace(key.clone()) {
                return Err(bad(format!("tensors `{other}` and `{key}` both give the same factor of one module")));
            }
        }
        let mut modules = Vec::new();
        for ((component, key), (address, parts)) in grouped {
            let (Some(down), Some(up)) = (parts.down, parts.up) else {
                return Err(bad(format!(
                    "module `{key}` needs both a down (lora_down / lora_A) and an up (lora_up / lora_B) factor"
                )));
            };
            let (down_shape, up_shape) = (file.entries[&down].shape.clone(), file.entries[&up].shape.clone());
            let r = down_shape.first().copied().unwrap_or(0);
            let linear_or_conv = |s: &[usize]| s.len() == 2 || s.len() == 4;
            if r == 0
                || !linear_or_conv(&down_shape)
                || !linear_or_conv(&up_shape)
                || up_shape[1] != r
                || up_shape[2..].iter().any(|&d| d != 1)
            {
                return Err(bad(format!(
                    "module `{key}`: down {down_shape:?} and up {up_shape:?} are not LoRA factors ([r, in(, kh, kw)] \
                        and [out, r(, 1, 1)])"
                )));
            }
            let scale = match (&parts.alpha, &address) {
                (Some(alpha), _) => {
                    let (_, v) = file.values(alpha)?;
                    let [alpha] = v[..] else {
                        return Err(bad(format!("alpha `{alpha}` holds {} values, not one", v.len())));
                    };
                    alpha / r as f32
                }
                (None, Address::Path(p)) => peft.scale(component, p, r),
                // kohya: no alpha means alpha = r.
                (None, Address::Kohya(_)) => 1.0,
            };
            modules.push(Module { key, component, address, down_shape, up_shape, scale, down, up });
        }
        Ok(LoraFile { path: path.to_path_buf(), modules, file })
    }

    /// A module's factors as f32: (up [out, r], down [r, in·kh·kw]), row-major as stored.
    pub fn factors(&self, module: &Module) -> Result<(Vec<f32>, Vec<f32>)> {
        Ok((self.file.values(&module.up)?.1, self.file.values(&module.down)?.1))
    }
}

/// Splits a tensor name into its component, target address, module key and role; `Err` says
/// what kind of tensor it is when vkdiff cannot use it.
fn classify(key: &str) -> std::result::Result<(Component, Address, String, Role), String> {
    if let Some(what) = lycoris(key) {
        return Err(what.into());
    }
    for (prefix, component) in KOHYA {
        let Some(rest) = key.strip_prefix(prefix) else { continue };
        let Some((name, suffix)) = rest.split_once('.') else {
            return Err("a kohya name without a `.lora_down` / `.lora_up` / `.alpha` suffix".into());
        };
        let role = match suffix {
            "lora_down.weight" => Role::Down,
            "lora_up.weight" => Role::Up,
            "alpha" => Role::Alpha,
            _ => return Err(format!("an unknown kohya tensor kind `.{suffix}`")),
        };
        return Ok((component, Address::Kohya(name.into()), format!("{prefix}{name}"), role));
    }
    if let Some(rest) = key.strip_prefix(COMFY_UNET) {
        let (path, role) = diffusers_module(rest, Component::Unet)?;
        return Ok((Component::Unet, Address::Kohya(path.replace('.', "_")), format!("{COMFY_UNET}{path}"), role));
    }
    let unwrapped = key.strip_prefix(PEFT_WRAPPER).unwrap_or(key);
    if UNET_MODULES.iter().any(|m| unwrapped.starts_with(m)) {
        return diffusers_key(Component::Unet, "", unwrapped);
    }
    for (prefix, component) in DIFFUSERS {
        let Some(rest) = key.strip_prefix(prefix) else { continue };
        return diffusers_key(component, prefix, rest.strip_prefix(PEFT_WRAPPER).unwrap_or(rest));
    }
    if unwrapped != key {
        return Err("a PEFT adapter without its component (`unet.` / `text_encoder.` / `text_encoder_2.`): which \
            network it adapts is not in the file"
            .into());
    }
    Err("not part of any LoRA layout vkdiff knows (kohya `lora_unet_` / `lora_te1_` / `lora_te2_`, diffusers `unet.` \
        / `text_encoder.` / `text_encoder_2.`, ComfyUI `diffusion_model.` / `text_encoders.`)"
        .into())
}

/// A diffusers / PEFT tensor of `component` whose module path (after `prefix`) is `rest`.
fn diffusers_key(
    component: Component,
    prefix: &str,
    rest: &str,
) -> std::result::Result<(Component, Address, String, Role), String> {
    // PEFT names the adapter inside the key (`lora_A.default.weight`).
    let rest = rest.replace(".default.", ".");
    let (path, role) = diffusers_module(&rest, component)?;
    Ok((component, Address::Path(path.clone()), format!("{prefix}{path}"), role))
}

/// Names of LyCORIS / DoRA tensors, which look like LoRA but need other algebra.
fn lycoris(key: &str) -> Option<&'static str> {
    let last = key.rsplit('.').nth(if key.ends_with(".weight") { 1 } else { 0 }).unwrap_or("");
    Some(match last {
        s if s.starts_with("hada_") => "a LyCORIS LoHa factor",
        s if s.starts_with("lokr_") => "a LyCORIS LoKr factor",
        "dora_scale" | "lora_magnitude_vector" => "a DoRA magnitude",
        "lora_mid" => "a LyCORIS LoCon Tucker core (lora_mid)",
        "diff" | "diff_b" | "set_weight" => "a full weight difference",
        "w_norm" | "b_norm" => "a norm-layer delta",
        _ if key.contains(".lora_magnitude_vector") => "a DoRA magnitude",
        _ if key.ends_with(".lora_A.bias") || key.ends_with(".lora_B.bias") => "a LoRA bias",
        _ => return None,
    })
}

/// The module path and role of a diffusers / PEFT tensor name (after its component prefix).
fn diffusers_module(rest: &str, component: Component) -> std::result::Result<(String, Role), String> {
    const SUFFIXES: [(&str, Role); 11] = [
        (".lora_A.weight", Role::Down),
        (".lora_B.weight", Role::Up),
        (".lora_down.weight", Role::Down),
        (".lora_up.weight", Role::Up),
        (".lora_linear_layer.down.weight", Role::Down),
        (".lora_linear_layer.up.weight", Role::Up),
        (".lora.down.weight", Role::Down),
        (".lora.up.weight", Role::Up),
        ("_lora.down.weight", Role::Down),
        ("_lora.up.weight", Role::Up),
        (".alpha", Role::Alpha),
    ];
    for (suffix, role) in SUFFIXES {
        let Some(stem) = rest.strip_suffix(suffix) else { continue };
        if !suffix.starts_with('_') {
            return Ok((stem.into(), role));
        }
        // Old attention-processor spelling: `attn1.processor.to_q_lora`, `to_out_lora` = to_out.0;
        // in the text encoders `self_attn.to_q_lora` = self_attn.q_proj.
        let (parent, proj) = stem.rsplit_once('.').unwrap_or(("", stem));
        let parent = parent.strip_suffix(".processor").unwrap_or(parent);
        let proj = match (component, proj) {
            (Component::Unet, "to_out") => "to_out.0".to_string(),
            (Component::Unet, p) => p.to_string(),
            (_, "to_out") => "out_proj".to_string(),
            (_, p) => format!("{}_proj", p.strip_prefix("to_").unwrap_or(p)),
        };
        return Ok((if parent.is_empty() { proj } else { format!("{parent}.{proj}") }, role));
    }
    Err("a diffusers tensor that is neither a LoRA factor (`lora_A` / `lora_B`, `lora.down` / `lora.up`) nor an alpha"
        .into())
}
