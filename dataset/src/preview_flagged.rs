//! `vkdiff dataset preview --flagged`: what the audit (audit.json) found, for the preview to
//! show only the flagged images, with the flagged instances outlined and the invented
//! detections boxed in the warning colour.

use crate::audit::read_audit;
use crate::error::Result;
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Flagged instances' outlines and invented detections' boxes.
pub const WARNING: [u8; 3] = [255, 0, 0];

/// One flagged image's findings.
pub struct ImageFlags {
    pub kinds: Vec<String>,
    /// The annotation ids of its flagged instances.
    pub instances: BTreeSet<u64>,
    /// The invented detections' boxes, x, y, w, h.
    pub boxes: Vec<[f64; 4]>,
}

/// The audit's flagged images, by image id.
pub struct Flagged(pub BTreeMap<u64, ImageFlags>);

impl Flagged {
    /// Reads DIR/audit.json, refusing a set that has not been audited.
    pub fn read(dir: &Path) -> Result<Flagged> {
        let audit = read_audit(dir, "to show")?;
        let images = audit["images"].as_array().into_iter().flatten();
        let mut flagged = BTreeMap::new();
        for image in images {
            let kinds: Vec<String> = image["flags"]
                .as_array()
                .into_iter()
                .flatten()
                .filter_map(|f| f.as_str().map(str::to_string))
                .collect();
            if kinds.is_empty() {
                continue;
            }
            let Some(id) = image["id"].as_u64() else { continue };
            let instances = image["worst"]
                .as_array()
                .into_iter()
                .flatten()
                .filter(|a| a["flags"].as_array().is_some_and(|f| !f.is_empty()))
                .filter_map(|a| a["id"].as_u64())
                .collect();
            let boxes = image["invented"]
                .as_array()
                .into_iter()
                .flatten()
                .filter_map(|d| serde_json::from_value(d["bbox"].clone()).ok())
                .collect();
            flagged.insert(id, ImageFlags { kinds, instances, boxes });
        }
        Ok(Flagged(flagged))
    }
}

/// The pixels on the outline of box `b` (x, y, w, h) in a `w`×`h` picture scaled down by `f`.
pub fn box_outline(b: [f64; 4], (width, height): (usize, usize), f: usize) -> Vec<usize> {
    let clamp = |v: f64, n: usize| ((v / f as f64).round().max(0.0) as usize).min(n.saturating_sub(1));
    let (x0, y0) = (clamp(b[0], width), clamp(b[1], height));
    let (x1, y1) = (clamp(b[0] + b[2], width), clamp(b[1] + b[3], height));
    let across = (x0..=x1).flat_map(|x| [y0 * width + x, y1 * width + x]);
    let down = (y0..=y1).flat_map(|y| [y * width + x0, y * width + x1]);
    across.chain(down).collect()
}
