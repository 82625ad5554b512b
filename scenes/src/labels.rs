//! What every rendered scene becomes, whatever wrote it: depth with its background at +∞, and an
//! instance map whose ids (as the renderer numbered them, with gaps) become 1..K in ascending
//! order over the instances that show, each with its category.

use crate::SceneError;
use serde_json::{Map, Value};
use std::collections::BTreeMap;
use vkdiff_render::frame::{Frame, Instance};

/// One scene as read from its files, before it becomes a [`Frame`].
pub struct RawScene {
    pub width: u32,
    pub height: u32,
    /// Depth (planar or along the ray), larger is farther.
    pub depth: Vec<f32>,
    /// The renderer's instance id per pixel; 0 is background.
    pub labels: Vec<u32>,
    /// Renderer id → category id; a category of 0 is background (BlenderProc's world).
    pub category_of: BTreeMap<u32, u32>,
    /// Renderer id → what its annotation records besides its mask (BlenderProc: the object's name).
    pub attributes: BTreeMap<u32, Map<String, Value>>,
    /// The renderer's own image, 8-bit RGB.
    pub shaded: Option<Vec<u8>>,
}

impl RawScene {
    /// The frame: depth at or past `far` (and NaN, infinite, zero or negative) is background;
    /// instances whose category is 0, or that have no pixel, are dropped.
    pub fn into_frame(self, far: f32) -> Result<(Frame, Option<Vec<u8>>), SceneError> {
        let n = (self.width as usize) * (self.height as usize);
        if self.depth.len() != n || self.labels.len() != n {
            return Err(SceneError::new(format!(
                "the depth ({} values) and the instance map ({} values) do not both hold its {}×{} pixels",
                self.depth.len(),
                self.labels.len(),
                self.width,
                self.height
            )));
        }
        let mut shown: BTreeMap<u32, u64> = BTreeMap::new();
        for &label in self.labels.iter().filter(|&&l| l != 0) {
            *shown.entry(label).or_default() += 1;
        }
        if let Some(label) = shown.keys().find(|l| !self.category_of.contains_key(l)) {
            return Err(SceneError::new(format!("instance {label} of the instance map has no category")));
        }
        let kept: Vec<u32> = shown.keys().copied().filter(|l| self.category_of[l] != 0).collect();
        if kept.len() > u16::MAX as usize - 1 {
            return Err(SceneError::new(format!("{} instances, more than a 16-bit mask holds (65534)", kept.len())));
        }
        let id_of: BTreeMap<u32, u16> = kept.iter().enumerate().map(|(k, &l)| (l, k as u16 + 1)).collect();
        let ids = self.labels.iter().map(|l| id_of.get(l).copied().unwrap_or(0)).collect();
        let background = |z: f32| !z.is_finite() || z <= 0.0 || z >= far;
        let depth = self.depth.into_iter().map(|z| if background(z) { f32::INFINITY } else { z }).collect();
        let instances = kept
            .iter()
            .map(|l| Instance {
                category_id: self.category_of[l],
                attributes: self.attributes.get(l).cloned().unwrap_or_default(),
            })
            .collect();
        let frame = Frame { width: self.width, height: self.height, camera: None, depth, ids, instances };
        Ok((frame, self.shaded))
    }
}
