//! A prompt and a strength per category: what categories.json and the flags say, checked once,
//! and each image's masks and strength map made from its labels (feathered and on the latent
//! grid, as `vkdiff_pipeline`'s denoiser blends and holds them).

use crate::error::{Error, Result};
use serde_json::{json, Map, Value};
use std::collections::BTreeMap;
use vkdiff_pipeline::images::masks::{feather, region_masks, relative_strengths};
use vkdiff_render::coco::Category;
use vkdiff_render::frame::Frame;
use vkdiff_scenes::CategoryGuide;
use vkdiff_setting::Message;

/// The region flags as given: `--category-prompt`, `--category-strength`,
/// `--background-strength`, `--region-feather`.
#[derive(Clone, Debug, Default)]
pub struct RegionFlags {
    pub prompts: Vec<(String, String)>,
    pub strengths: Vec<(String, f64)>,
    pub background: Option<f64>,
    pub feather: usize,
}

/// What a set's regions are: none by default, so that a set made without them is what it was.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RegionSettings {
    /// Prompted categories, in id order: (id, name, prompt).
    pub prompts: Vec<(u32, String, String)>,
    /// Each category's strength where it differs from the rest's, by id: (name, strength).
    pub strengths: BTreeMap<u32, (String, f64)>,
    /// The background's strength, where it differs from the rest's.
    pub background: Option<f64>,
    /// The strength of every other pixel: `--init-strength`, else 1.
    pub rest: f64,
    pub feather: usize,
    /// Pixels per latent along a side (the VAE's downscale).
    pub latent_scale: usize,
}

/// One image's region inputs, on the latent grid, and its strength map as a picture.
pub struct ImageRegions {
    pub masks: Option<Vec<Vec<f32>>>,
    pub strength: Option<Vec<f64>>,
    /// The feathered strength at the image's size as 8-bit grey levels (0 to 1 as 0 to 255).
    pub strength_picture: Option<Vec<u8>>,
}

fn strength_ok(setting: &str, what: &str, s: f64) -> Result<f64> {
    if s > 0.0 && s <= 1.0 {
        return Ok(s);
    }
    Err(Error::Setting(Message::setting(setting).then(format!(" {what}{s} must be in (0, 1]"))))
}

impl RegionSettings {
    /// The regions of a set of `categories` from what the scenes' categories.json files say
    /// (`guides`) and the flags (which win); `init_strength` is the rest's strength.
    pub fn new(
        categories: &[Category],
        guides: &BTreeMap<u32, CategoryGuide>,
        flags: &RegionFlags,
        init_strength: Option<f64>,
        latent_scale: usize,
    ) -> Result<RegionSettings> {
        let id_of = |setting: &str, name: &str| -> Result<u32> {
            let found = categories.iter().find(|c| c.name == name.trim()).map(|c| c.id);
            found.ok_or_else(|| {
                let names: Vec<&str> = categories.iter().map(|c| c.name.as_str()).collect();
                Error::Setting(
                    Message::setting(setting)
                        .then(format!(" {name}=: no such category (the scenes have {})", names.join(", "))),
                )
            })
        };
        let mut prompts: BTreeMap<u32, String> =
            guides.iter().filter_map(|(&id, g)| Some((id, g.prompt.clone()?))).collect();
        for (name, prompt) in &flags.prompts {
            if prompt.trim().is_empty() {
                return Err(Error::Setting(Message::setting("category_prompt").then(format!(" {name}= is empty"))));
            }
            prompts.insert(id_of("category_prompt", name)?, prompt.clone());
        }
        let mut strengths: BTreeMap<u32, f64> = guides.iter().filter_map(|(&id, g)| Some((id, g.strength?))).collect();
        for (name, s) in &flags.strengths {
            strengths
                .insert(id_of("category_strength", name)?, strength_ok("category_strength", &format!("{name}="), *s)?);
        }
        let rest = init_strength.unwrap_or(1.0);
        let background = flags.background.map(|s| strength_ok("background_strength", "", s)).transpose()?;
        let name = |id: u32| categories.iter().find(|c| c.id == id).map_or(String::new(), |c| c.name.clone());
        // A strength equal to the rest's changes nothing, and is not recorded.
        Ok(RegionSettings {
            prompts: prompts.into_iter().map(|(id, p)| (id, name(id), p)).collect(),
            strengths: strengths.into_iter().filter(|&(_, s)| s != rest).map(|(id, s)| (id, (name(id), s))).collect(),
            background: background.filter(|&s| s != rest),
            rest,
            feather: flags.feather,
            latent_scale,
        })
    }

    pub fn has_prompts(&self) -> bool {
        !self.prompts.is_empty()
    }

    /// Whether pixels have strengths of their own (else the set is plain img2img, or none).
    pub fn has_strengths(&self) -> bool {
        !self.strengths.is_empty() || self.background.is_some()
    }

    /// The largest strength: the schedule's img2img strength.
    pub fn largest(&self) -> f64 {
        self.strengths.values().map(|(_, s)| *s).chain(self.background).fold(self.rest, f64::max)
    }

    /// The settings dataset.json records, none without regions.
    pub fn to_json(&self) -> Map<String, Value> {
        let mut map = Map::new();
        if self.has_prompts() {
            let prompts: Map<String, Value> = self.prompts.iter().map(|(_, n, p)| (n.clone(), json!(p))).collect();
            map.insert("category-prompts".into(), Value::Object(prompts));
        }
        if !self.strengths.is_empty() {
            let strengths: Map<String, Value> = self.strengths.values().map(|(n, s)| (n.clone(), json!(s))).collect();
            map.insert("category-strengths".into(), Value::Object(strengths));
        }
        if let Some(s) = self.background {
            map.insert("background-strength".into(), json!(s));
        }
        if self.has_prompts() || self.has_strengths() {
            map.insert("region-feather".into(), json!(self.feather));
        }
        map
    }

    /// The PNG text of an image with these regions, none without them.
    pub fn png_text(&self) -> Vec<(String, String)> {
        let mut text = Vec::new();
        if self.has_prompts() {
            let lines: Vec<String> = self.prompts.iter().map(|(_, n, p)| format!("{n}={p}")).collect();
            text.push(("region_prompts".into(), lines.join("\n")));
        }
        if !self.strengths.is_empty() {
            let lines: Vec<String> = self.strengths.values().map(|(n, s)| format!("{n}={s}")).collect();
            text.push(("category_strengths".into(), lines.join("\n")));
        }
        if let Some(s) = self.background {
            text.push(("background_strength".into(), s.to_string()));
        }
        if self.has_prompts() || self.has_strengths() {
            text.push(("region_feather".into(), self.feather.to_string()));
        }
        text
    }

    /// `part`'s masks (the scene prompt's, then each prompted category's) and strength map.
    pub fn of_image(&self, part: &Frame) -> ImageRegions {
        if !self.has_prompts() && !self.has_strengths() {
            return ImageRegions { masks: None, strength: None, strength_picture: None };
        }
        let (w, h) = (part.width(), part.height());
        let latent = (w / self.latent_scale, h / self.latent_scale);
        let categories: Vec<u32> =
            part.ids.iter().map(|&id| if id == 0 { 0 } else { part.instances[id as usize - 1].category_id }).collect();
        let masks = self.has_prompts().then(|| {
            let prompted: Vec<u32> = self.prompts.iter().map(|(id, _, _)| *id).collect();
            region_masks(&categories, w, h, &prompted, self.feather, latent)
        });
        let (strength, strength_picture) = if self.has_strengths() {
            let per_pixel: Vec<f64> = (categories.iter())
                .map(|c| match (c, self.background) {
                    (0, Some(b)) => b,
                    _ => self.strengths.get(c).map_or(self.rest, |(_, s)| *s),
                })
                .collect();
            let map = relative_strengths(&per_pixel, w, h, self.largest(), self.feather, latent);
            let soft = feather(&per_pixel, w, h, self.feather);
            let grey: Vec<u8> = soft.iter().map(|s| (s * 255.0).round().clamp(0.0, 255.0) as u8).collect();
            (Some(map), Some(grey))
        } else {
            (None, None)
        };
        ImageRegions { masks, strength, strength_picture }
    }
}
