//! What dataset.json records of a set's settings: every setting that shapes the output, under its
//! flag's name, and the first in which a folder's record and a run's settings differ.

use crate::settings::DatasetSettings;
use serde_json::{json, Map, Value};
use vkdiff_pipeline::{control_depth_name, precision_name, recorded_path, schedule_name, schedule_records, RNG};
use vkdiff_pipeline::{IpScale, ModelSettings, PromptSyntax, SizeConditioning};
use vkdiff_setting::Message;

impl DatasetSettings {
    /// Every setting that shapes the output, under its flag's name.
    pub fn to_json(&self) -> Value {
        let s = &self.sampling;
        let mut v = json!({
            "seed": self.seed,
            "count": self.count,
            "crops": self.crops.count,
            "crop-size": self.crops.size,
            "crop-min-fraction": self.crops.min_fraction,
            "control-depth": control_depth_name(self.control_depth),
            "image-size": [s.width, s.height],
        });
        let map = v.as_object_mut().expect("an object");
        map.extend(self.source.settings());
        map.extend(self.controls.to_json());
        map.extend(self.regions.to_json());
        match &self.models {
            Some(models) => map.extend(self.diffusion_json(models)),
            None => {
                map.insert("render-only".into(), json!(true));
            }
        }
        v
    }

    /// The settings of the images' diffusion.
    fn diffusion_json(&self, m: &ModelSettings) -> Map<String, Value> {
        let s = &self.sampling;
        let mut map = object(json!({
            "model": recorded_path(&m.model),
            "precision": precision_name(m.precision),
            "prompt": self.prompts,
            "negative-prompt": self.negative_prompt,
            "steps": s.steps,
            "cfg": s.guidance_scale,
            "sampler": s.sampler.to_string(),
            "scheduler": schedule_name(s),
            "rng": RNG,
            "lora": m.lora_flags(),
        }));
        map.extend(schedule_records(s).into_iter().map(|(k, v)| (k.to_string(), v)));
        let c = &s.size_conditioning;
        let size = |s: Option<(usize, usize)>| s.map(|(w, h)| format!("{w}x{h}"));
        if s.prompt_syntax == PromptSyntax::Weighted {
            map.insert("prompt-syntax".into(), json!("weighted"));
        }
        if let Some(dir) = self.wildcards.dir() {
            map.insert("wildcards".into(), json!(dir.display().to_string()));
            map.insert("wildcards-hash".into(), json!(self.wildcards.digest()));
        }
        match (s.strength, self.regions.has_strengths()) {
            (Some(strength), false) => {
                map.insert("init-strength".into(), json!(strength));
            }
            // The rest's strength; the schedule's is the largest.
            (Some(_), true) if self.regions.rest != 1.0 => {
                map.insert("init-strength".into(), json!(self.regions.rest));
            }
            _ => {}
        }
        if let Some(vae) = &m.vae {
            map.insert("vae".into(), json!(recorded_path(vae)));
        }
        if let Some(unet) = &m.unet {
            map.insert("unet".into(), json!(recorded_path(unet)));
        }
        if *c != SizeConditioning::default() {
            map.extend(object(json!({
                "original-size": size(c.original),
                "crops-coords-top-left": format!("{},{}", c.crop_top_left.0, c.crop_top_left.1),
                "target-size": size(c.target),
            })));
        }
        match &m.controlnets[..] {
            [] => {}
            [c] if c.is_depth_only() => map.extend(object(json!({
                "controlnet": recorded_path(&c.model),
                "control-scale": c.scale,
                "control-start": c.start,
                "control-end": c.end,
            }))),
            nets => {
                let nets: Vec<Value> = (nets.iter())
                    .map(|c| {
                        json!({
                            "model": recorded_path(&c.model),
                            "controls": c.controls.iter().map(|k| k.name()).collect::<Vec<_>>(),
                            "scale": c.scale,
                            "start": c.start,
                            "end": c.end,
                        })
                    })
                    .collect();
                map.insert("controlnets".into(), Value::Array(nets));
            }
        }
        if let Some(ip) = &m.ip_adapter {
            let sets: Vec<Vec<String>> =
                self.ip_sets.iter().map(|set| set.iter().map(|p| p.display().to_string()).collect()).collect();
            map.extend(object(json!({
                "ip-adapter": recorded_path(&ip.adapter),
                "image-encoder": recorded_path(&ip.encoder),
                "ip-scale": ip_scale_json(&ip.scale),
                "ip-set": sets,
            })));
        }
        map
    }
}

/// A number where it is one (as earlier datasets recorded it), else the flag's text.
fn ip_scale_json(scale: &IpScale) -> Value {
    match scale {
        IpScale::All(s) => json!(s),
        blocks => json!(blocks.to_string()),
    }
}

fn object(v: Value) -> Map<String, Value> {
    match v {
        Value::Object(map) => map,
        _ => unreachable!("built from an object literal"),
    }
}

/// The first setting in which `recorded` and `wanted` differ, as a one-line refusal (the keys
/// of dataset.json's settings are the settings' names with dashes).
pub fn first_difference(recorded: &Value, wanted: &Value) -> Option<Message> {
    let (a, b) = (recorded.as_object()?, wanted.as_object()?);
    let keys: std::collections::BTreeSet<&String> = a.keys().chain(b.keys()).collect();
    keys.into_iter().find(|k| a.get(*k) != b.get(*k)).map(|k| {
        let show = |v: Option<&Value>| v.map_or("(not set)".to_string(), |v| v.to_string());
        let named = match k.as_str() {
            "image-size" => {
                Message::text("the image size (from ").and("crop_size").then(", or the frame and the model)")
            }
            "ip-set" => Message::setting("ip_image").then("/").and("ip_set"),
            "prompt" => Message::setting("prompt").then("/").and("prompts"),
            "wildcards-hash" => Message::text("the content of the ").and("wildcards").then(" files"),
            "cfg" => Message::setting("guidance_scale"),
            "init-strength" => Message::setting("strength"),
            other => Message::setting(other.replace('-', "_")),
        };
        named.then(format!(" was {} there, {} now", show(a.get(k)), show(b.get(k))))
    })
}
