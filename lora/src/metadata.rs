//! The PEFT adapter configs diffusers writes into a LoRA file's safetensors header
//! (`__metadata__.lora_adapter_metadata`: a JSON string holding one flat object whose keys carry
//! the component, `unet.lora_alpha`, `text_encoder.alpha_pattern`, ...), resolved the way PEFT
//! resolves them into a per-module scale.

use crate::component::Component;
use crate::error::{Error, Result};
use regex::Regex;
use serde_json::{Map, Value};
use std::collections::HashMap;
use std::io::Read;
use std::path::Path;
use vkdiff_formats::Error as FileError;

const METADATA_KEY: &str = "lora_adapter_metadata";
/// PEFT's `LoraConfig.lora_alpha` default, used when a config is present but names no alpha.
const PEFT_DEFAULT_ALPHA: f64 = 8.0;

struct PeftConfig {
    lora_alpha: f64,
    /// (pattern, alpha), in the order PEFT tries them (sorted keys, as diffusers writes them).
    alpha_pattern: Vec<(Regex, f64)>,
    use_rslora: bool,
}

/// Each component's PEFT config, where the file has one.
#[derive(Default)]
pub(crate) struct PeftConfigs {
    by_component: HashMap<Component, PeftConfig>,
}

impl PeftConfigs {
    pub fn read(path: &Path) -> Result<PeftConfigs> {
        let bad = |why: String| Error::from(FileError::Format { path: path.to_path_buf(), why });
        let Some(raw) = header_metadata(path)?.remove(METADATA_KEY) else { return Ok(PeftConfigs::default()) };
        let json: Map<String, Value> =
            serde_json::from_str(&raw).map_err(|e| bad(format!("`{METADATA_KEY}` is not a JSON object: {e}")))?;
        let mut by_component = HashMap::new();
        for (prefix, component) in [
            ("unet.", Component::Unet),
            ("text_encoder.", Component::TextEncoder1),
            ("text_encoder_2.", Component::TextEncoder2),
        ] {
            let field = |name: &str| json.get(&format!("{prefix}{name}"));
            if !json.keys().any(|k| k.starts_with(prefix)) {
                continue;
            }
            let wrong = |name: &str, want: &str| {
                bad(format!(
                    "`{prefix}{name}` in `{METADATA_KEY}` is {}, not {want}",
                    field(name).map_or(String::new(), Value::to_string)
                ))
            };
            let lora_alpha = match field("lora_alpha") {
                None | Some(Value::Null) => PEFT_DEFAULT_ALPHA,
                Some(v) => v.as_f64().ok_or_else(|| wrong("lora_alpha", "a number"))?,
            };
            let use_rslora = match field("use_rslora") {
                None | Some(Value::Null) => false,
                Some(v) => v.as_bool().ok_or_else(|| wrong("use_rslora", "true or false"))?,
            };
            let patterns = match field("alpha_pattern") {
                None | Some(Value::Null) => None,
                Some(Value::Object(p)) => Some(p),
                Some(_) => return Err(wrong("alpha_pattern", "an object")),
            };
            let mut alpha_pattern = Vec::new();
            if let Some(patterns) = patterns {
                for (pattern, alpha) in patterns {
                    let alpha = alpha
                        .as_f64()
                        .ok_or_else(|| bad(format!("alpha_pattern `{pattern}` of {prefix} is not a number")))?;
                    // PEFT: re.match(rf"(.*\.)?({key})$", module_name).
                    let re = Regex::new(&format!(r"^(?:.*\.)?(?:{pattern})$"))
                        .map_err(|e| bad(format!("alpha_pattern `{pattern}`: {e}")))?;
                    alpha_pattern.push((re, alpha));
                }
            }
            by_component.insert(component, PeftConfig { lora_alpha, alpha_pattern, use_rslora });
        }
        Ok(PeftConfigs { by_component })
    }

    /// The scale of module `path` of rank `r`: alpha / r (alpha / √r with rsLoRA); 1 without a config.
    pub fn scale(&self, component: Component, path: &str, r: usize) -> f32 {
        let Some(c) = self.by_component.get(&component) else { return 1.0 };
        let alpha = c.alpha_pattern.iter().find(|(re, _)| re.is_match(path)).map_or(c.lora_alpha, |(_, a)| *a);
        let r = r as f64;
        (if c.use_rslora { alpha / r.sqrt() } else { alpha / r }) as f32
    }
}

/// The string entries of a safetensors header's `__metadata__` (the shared reader skips them).
fn header_metadata(path: &Path) -> Result<HashMap<String, String>> {
    let io = |e| Error::from(FileError::Io { path: path.to_path_buf(), source: e });
    let mut file = std::fs::File::open(path).map_err(io)?;
    let mut len = [0u8; 8];
    file.read_exact(&mut len).map_err(io)?;
    let mut header = vec![0u8; u64::from_le_bytes(len) as usize];
    // SafeTensors::open has already checked the length against the file.
    file.read_exact(&mut header).map_err(io)?;
    let json: Value = serde_json::from_slice(&header)
        .map_err(|e| FileError::Format { path: path.to_path_buf(), why: format!("header is not JSON: {e}") })?;
    let Some(Value::Object(meta)) = json.get("__metadata__") else { return Ok(HashMap::new()) };
    Ok(meta.iter().filter_map(|(k, v)| Some((k.clone(), v.as_str()?.to_string()))).collect())
}
