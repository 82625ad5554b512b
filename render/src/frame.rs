//! A labelled frame: planar depth, instance ids 1..K (0 = background), and what each instance is
//! (its category, and attributes the annotations carry). The procedural bed numbers its visible
//! mushrooms in bed order; frames rendered elsewhere come numbered in the order of their ids.
//! Instances with no visible pixel get no id, so ids match the COCO annotation ids one to one.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::bed::Bed;
use crate::camera::Camera;
use crate::geometry::{AmodalMask, Keypoint};
use crate::raster::RasterImage;

/// What a mushroom of the procedural bed is, written next to its mask in the COCO annotation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct InstanceInfo {
    /// Index of the mushroom in the bed: the same mushroom has the same index in the full frame
    /// and in every crop.
    pub bed_index: usize,
    pub age: f64,
    pub cap_diameter_mm: f64,
    /// Where the stem meets the compost, world coordinates in metres (see camera.json).
    pub position_m: [f64; 3],
    pub yaw_deg: f64,
    pub tilt_deg: [f64; 2],
    /// Growth row (one seed each) and stage of the variant this instance was drawn from.
    pub variant_row: usize,
    pub variant_stage: usize,
}

impl InstanceInfo {
    /// As annotation fields.
    pub fn attributes(&self) -> serde_json::Map<String, serde_json::Value> {
        match serde_json::to_value(self).expect("numbers always serialise") {
            serde_json::Value::Object(map) => map,
            _ => unreachable!("a struct serialises to an object"),
        }
    }
}

/// One instance of a frame: its COCO category, and what else its annotation records.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Instance {
    pub category_id: u32,
    /// Extra annotation fields (the procedural bed's: [`InstanceInfo`]'s; a renderer's pose and
    /// 3D box, in [`crate::geometry`]'s conventions).
    pub attributes: serde_json::Map<String, serde_json::Value>,
    /// Its keypoints in the frame's pixels, as its category names them; empty when it has none.
    pub keypoints: Vec<Keypoint>,
    /// Its whole shape, hidden parts too, where the renderer gives it.
    pub amodal: Option<AmodalMask>,
}

impl Instance {
    /// This instance as the `width`×`height` window at (x0, y0) of its frame shows it.
    pub fn in_window(&self, x0: u32, y0: u32, width: u32, height: u32) -> Instance {
        Instance {
            category_id: self.category_id,
            attributes: self.attributes.clone(),
            keypoints: self.keypoints.iter().map(|k| k.in_window(x0, y0, width, height)).collect(),
            amodal: self.amodal.as_ref().and_then(|m| m.in_window(x0, y0, width, height)),
        }
    }
}

/// The procedural bed's only category.
pub const MUSHROOM: u32 = 1;

#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    /// The camera it was seen by, where known (the procedural bed's; a scene folder's
    /// camera.json).
    pub camera: Option<Camera>,
    /// Planar depth in metres, row-major; +∞ where nothing was drawn.
    pub depth: Vec<f32>,
    /// 0 = background, k = `instances[k - 1]`.
    pub ids: Vec<u16>,
    pub instances: Vec<Instance>,
    /// The renderer's own surface normals, where the scene gives them, row-major: camera space in
    /// OpenCV's axes (x right, y down, z forward, as camera.json's OpenCV pose), each the normal
    /// of the surface seen at that pixel, pointing out of it (a surface facing the camera has
    /// z < 0); any length. A zero or non-finite normal is unknown.
    pub normals: Option<Vec<[f32; 3]>>,
}

impl Frame {
    pub fn width(&self) -> usize {
        self.width as usize
    }

    pub fn height(&self) -> usize {
        self.height as usize
    }

    /// Focal lengths in pixels: the camera's, else Blender's default lens (50 mm on a 36 mm
    /// sensor across the width), for shading a frame seen by an unknown camera.
    pub fn focal(&self) -> (f64, f64) {
        match &self.camera {
            Some(c) => (c.fx, c.fy),
            None => {
                let f = self.width as f64 * 50.0 / 36.0;
                (f, f)
            }
        }
    }

    /// Keeps the visible mushrooms of `raster` (raster id = bed index + 1), numbered 1..K in bed
    /// order; `camera` and `bed` are the scene's it was rasterized from.
    pub fn from_raster(raster: RasterImage, camera: &Camera, bed: &Bed) -> Frame {
        let counts = pixel_counts(&raster.ids, bed.instances.len() + 1);
        let mut ids = raster.ids;
        let kept = renumber(&mut ids, counts.len(), |raw| counts[raw] > 0);
        let instances = kept
            .iter()
            .map(|&raw| Instance {
                category_id: MUSHROOM,
                attributes: instance_info(bed, raw - 1).attributes(),
                ..Instance::default()
            })
            .collect();
        Frame {
            width: camera.width,
            height: camera.height,
            camera: Some(camera.clone()),
            depth: raster.depth,
            ids,
            instances,
            normals: None,
        }
    }
}

/// Renumbers the labels 1..`labels` that `keep` accepts to 1..K in order, in place (0 and the
/// labels dropped become 0); returns the labels kept, in order.
pub fn renumber(ids: &mut [u16], labels: usize, keep: impl Fn(usize) -> bool) -> Vec<usize> {
    let kept: Vec<usize> = (1..labels).filter(|&label| keep(label)).collect();
    let mut map = vec![0u16; labels];
    kept.iter().enumerate().for_each(|(k, &label)| map[label] = k as u16 + 1);
    ids.par_iter_mut().for_each(|id| *id = map[*id as usize]);
    kept
}

/// Pixels per id for ids below `labels`.
pub fn pixel_counts(ids: &[u16], labels: usize) -> Vec<u64> {
    ids.par_chunks(1 << 16)
        .map(|chunk| {
            let mut counts = vec![0u64; labels];
            chunk.iter().for_each(|&id| counts[id as usize] += 1);
            counts
        })
        .reduce(
            || vec![0u64; labels],
            |mut a, b| {
                a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
                a
            },
        )
}

fn instance_info(bed: &Bed, bed_index: usize) -> InstanceInfo {
    let instance = &bed.instances[bed_index];
    let variant = &bed.variants[instance.variant];
    InstanceInfo {
        bed_index,
        age: variant.params.age,
        cap_diameter_mm: variant.params.cap_diameter() * 1e3,
        position_m: instance.base.to_array(),
        yaw_deg: instance.yaw.to_degrees(),
        tilt_deg: [instance.tilt.0.to_degrees(), instance.tilt.1.to_degrees()],
        variant_row: variant.row,
        variant_stage: variant.stage,
    }
}
