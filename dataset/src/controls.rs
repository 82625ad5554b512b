//! The control images made beside the depth control (`--controls`), each computed exactly from its
//! image's labels (docs/controls.md): written as `control/NNNNNN.<kind>.png`, listed in the
//! image's COCO entry under `control_files`, and recorded in dataset.json with the segmentation's
//! colours.

use crate::error::{Error, Result};
use serde_json::{json, Map, Value};
use vkdiff_render::coco::Category;
use vkdiff_render::control::edges::{edge_image, DEFAULT_DEPTH_JUMP};
use vkdiff_render::control::normals::{normal_image, Intrinsics};
use vkdiff_render::control::segmentation::{category_colours, segmentation_image, CategoryColour};
use vkdiff_render::control::ControlKind;
use vkdiff_render::crops::CropWindow;
use vkdiff_render::frame::Frame;
use vkdiff_setting::Message;

/// Which controls each image gets besides its depth control, and how they are made.
#[derive(Clone, Debug, PartialEq)]
pub struct LabelControls {
    /// In [`ControlKind`]'s order, without depth (always made) and without repeats.
    pub kinds: Vec<ControlKind>,
    /// The relative depth jump that makes an edge (and ends a surface, for the normals).
    pub depth_jump: f32,
    /// Each category's colour in the segmentation.
    pub colours: Vec<CategoryColour>,
}

impl Default for LabelControls {
    fn default() -> LabelControls {
        LabelControls { kinds: Vec::new(), depth_jump: DEFAULT_DEPTH_JUMP, colours: Vec::new() }
    }
}

impl LabelControls {
    /// `kinds` for a set of `categories`; a jump that is not a positive number is refused.
    pub fn new(kinds: &[ControlKind], depth_jump: f32, categories: &[Category]) -> Result<LabelControls> {
        if !(depth_jump.is_finite() && depth_jump > 0.0) {
            let why = format!(" {depth_jump} must be a positive fraction of the nearer depth");
            return Err(Error::Setting(Message::setting("edge_depth_jump").then(why)));
        }
        let mut kinds: Vec<ControlKind> = kinds.iter().copied().filter(|&k| k != ControlKind::Depth).collect();
        kinds.sort();
        kinds.dedup();
        let colours = if kinds.contains(&ControlKind::Segmentation) { category_colours(categories) } else { vec![] };
        Ok(LabelControls { kinds, depth_jump, colours })
    }

    /// The settings dataset.json records; none without extra controls, so a set made without
    /// them records what it always did.
    pub fn to_json(&self) -> Map<String, Value> {
        let mut map = Map::new();
        if self.kinds.is_empty() {
            return map;
        }
        map.insert("controls".into(), json!(self.kinds.iter().map(|k| k.name()).collect::<Vec<_>>()));
        map.insert("edge-depth-jump".into(), json!(self.depth_jump));
        if !self.colours.is_empty() {
            map.insert("segmentation-colours".into(), json!(self.colours));
        }
        map
    }

    /// The control images (RGB8) of `part`, the part of a `frame_size` frame under `window`;
    /// normals use the renderer's normals where the part has them, and for the rest its depth with
    /// the part's camera, else Blender's default camera of the whole frame.
    pub fn images(&self, part: &Frame, frame_size: (u32, u32), window: CropWindow) -> Vec<(ControlKind, Vec<u8>)> {
        let width = part.width as usize;
        let categories: Vec<u32> = part.instances.iter().map(|i| i.category_id).collect();
        let camera = part.camera.as_ref().map(Intrinsics::of).unwrap_or_else(|| {
            let whole = Intrinsics::blender_default(frame_size.0, frame_size.1);
            Intrinsics { cx: whole.cx - window.x0 as f64, cy: whole.cy - window.y0 as f64, ..whole }
        });
        self.kinds
            .iter()
            .map(|&kind| {
                let pixels = match kind {
                    ControlKind::Edges => edge_image(&part.ids, &part.depth, width, self.depth_jump),
                    ControlKind::Segmentation => segmentation_image(&part.ids, &categories, &self.colours),
                    ControlKind::Normals => {
                        normal_image(&part.ids, &part.depth, part.normals.as_deref(), width, camera, self.depth_jump)
                    }
                    ControlKind::Depth => unreachable!("the depth control is made on its own"),
                };
                (kind, pixels)
            })
            .collect()
    }
}

/// The file of control `kind` beside the depth control `control/NNNNNN.png`.
pub fn control_file(depth_control: &str, kind: ControlKind) -> String {
    let stem = depth_control.strip_suffix(".png").unwrap_or(depth_control);
    format!("{stem}.{}.png", kind.name())
}

#[cfg(test)]
mod tests {
    use super::*;
    use vkdiff_render::crops::crop_frame;
    use vkdiff_render::scene::SceneConfig;
    use vkdiff_scenes::{ProceduralBed, SceneSource};

    #[test]
    fn a_crops_controls_are_its_frames_controls_cut() {
        // A bed seen by its camera, and the same frame as a scene without one (Blender's default
        // camera of the whole frame, its principal point moved with the crop).
        let bed = ProceduralBed::new(SceneConfig { width: 320, height: 240, ..SceneConfig::default() }).unwrap();
        let frame = bed.frame(0, 7).unwrap().frame;
        let no_camera = Frame { camera: None, ..frame.clone() };
        let kinds = [ControlKind::Edges, ControlKind::Segmentation, ControlKind::Normals];
        let controls = LabelControls::new(&kinds, DEFAULT_DEPTH_JUMP, &bed.categories()).unwrap();
        let whole = CropWindow { x0: 0, y0: 0, width: 320, height: 240 };
        let window = CropWindow { x0: 70, y0: 50, width: 128, height: 96 };
        for f in [&frame, &no_camera] {
            let full = controls.images(f, (320, 240), whole);
            let cut = controls.images(&crop_frame(f, window, 0.0), (320, 240), window);
            assert!(f.ids.iter().filter(|&&id| id != 0).count() > 1000, "the frame shows mushrooms");
            for ((kind, full), (_, cut)) in full.iter().zip(&cut) {
                // One pixel in from the crop's border, where its neighbours are the frame's.
                let mut worst = 0;
                for y in 1..95 {
                    for x in 1..127 {
                        let (at_cut, at_full) = (3 * (y * 128 + x), 3 * ((y + 50) * 320 + x + 70));
                        for c in 0..3 {
                            worst = worst.max(cut[at_cut + c].abs_diff(full[at_full + c]));
                        }
                    }
                }
                assert!(worst == 0, "{kind:?}, camera {}: off by {worst}", f.camera.is_some());
            }
        }
    }
}
