//! COCO instance segmentation for a frame: annotation id = the instance id in instances.png
//! (1..K), each instance's category (the procedural bed's one: `mushroom`, id 1), compressed RLE
//! masks, `area` = mask pixel count, `bbox` from the mask, `iscrowd` 0, and the instance's
//! attributes (what each mushroom is) as extra fields.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use crate::frame::{Frame, MUSHROOM};
use crate::geometry::{BOX_KEYPOINTS, BOX_SKELETON};
use crate::rle::{PixelBox, Rle};

/// Where the frame's annotations point for the picture itself: the control image, the one image
/// of the folder that exists for every frame (the photoreal stage writes its own file_name).
pub const IMAGE_FILE: &str = "control.png";

/// The mask of one instance and the numbers COCO derives from it.
#[derive(Clone, Debug, PartialEq)]
pub struct InstanceMask {
    pub rle: Rle,
    pub bbox: PixelBox,
    pub area: u64,
}

/// Masks of instances 1..=K, computed in parallel; each reads only its own bounding box.
pub fn instance_masks(frame: &Frame) -> Vec<InstanceMask> {
    let (w, h) = (frame.width, frame.height);
    let bounds = instance_bounds(&frame.ids, w as usize, frame.instances.len());
    bounds
        .par_iter()
        .enumerate()
        .map(|(k, b)| {
            let bbox = b.expect("every instance of a frame has a visible pixel");
            let rle = Rle::from_labels(&frame.ids, w, h, k as u16 + 1, bbox);
            InstanceMask { area: rle.area(), rle, bbox }
        })
        .collect()
}

/// Bounding box of each id 1..=count, by rows in parallel.
fn instance_bounds(ids: &[u16], width: usize, count: usize) -> Vec<Option<PixelBox>> {
    let merge = |a: Option<PixelBox>, b: Option<PixelBox>| match (a, b) {
        (Some(a), Some(b)) => {
            Some(PixelBox { x0: a.x0.min(b.x0), y0: a.y0.min(b.y0), x1: a.x1.max(b.x1), y1: a.y1.max(b.y1) })
        }
        (a, b) => a.or(b),
    };
    ids.par_chunks(width)
        .enumerate()
        .fold(
            || vec![None; count + 1],
            |mut acc: Vec<Option<PixelBox>>, (y, row)| {
                for (x, &id) in row.iter().enumerate() {
                    if id != 0 {
                        let p = Some(PixelBox { x0: x as u32, y0: y as u32, x1: x as u32, y1: y as u32 });
                        acc[id as usize] = merge(acc[id as usize], p);
                    }
                }
                acc
            },
        )
        .reduce(|| vec![None; count + 1], |a, b| a.into_iter().zip(b).map(|(a, b)| merge(a, b)).collect())
        .split_off(1)
}

#[derive(Serialize)]
struct CocoFile<'a> {
    info: Value,
    images: [Image; 1],
    annotations: Vec<Annotation>,
    categories: &'a [Category],
    licenses: [(); 0],
}

#[derive(Serialize)]
struct Image {
    id: u32,
    file_name: &'static str,
    width: u32,
    height: u32,
}

/// A COCO category, as the scenes name it.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Category {
    pub id: u32,
    pub name: String,
    #[serde(default)]
    pub supercategory: String,
    /// The names of its instances' keypoints, in their order (COCO's person keypoints' form).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub keypoints: Vec<String>,
    /// Lines between keypoints, numbered from 1.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub skeleton: Vec<[u32; 2]>,
}

impl Category {
    pub fn new(id: u32, name: &str, supercategory: &str) -> Category {
        Category { id, name: name.into(), supercategory: supercategory.into(), ..Category::default() }
    }

    /// This category with the keypoints of a 3D box ([`BOX_KEYPOINTS`]).
    pub fn with_box_keypoints(self) -> Category {
        let keypoints = BOX_KEYPOINTS.iter().map(|k| k.to_string()).collect();
        Category { keypoints, skeleton: BOX_SKELETON.to_vec(), ..self }
    }
}

/// A compressed RLE mask, as pycocotools' `encode` writes it.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Segmentation {
    pub size: [u32; 2],
    pub counts: String,
}

/// One COCO annotation as vkdiff writes it, with the instance's attributes as extra fields.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Annotation {
    /// None only in a dataset's per-image records, which are numbered when merged.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub id: Option<u64>,
    pub image_id: u64,
    pub category_id: u32,
    pub segmentation: Segmentation,
    pub area: u64,
    pub bbox: [u32; 4],
    pub iscrowd: u8,
    /// In a dataset: the instance's value in the image's mask PNG (the annotation ids run over
    /// the whole set there, so they are not the mask's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mask_id: Option<u64>,
    /// COCO's keypoints, x, y, v for each of its category's, and how many are labelled (v > 0).
    #[serde(default, skip_serializing_if = "Option::is_none", serialize_with = "serialize_keypoints")]
    pub keypoints: Option<Vec<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub num_keypoints: Option<u32>,
    /// The whole shape, hidden parts too, with its box and area (COCOA's and KINS's amodal
    /// fields beside the visible `segmentation`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub amodal_segmentation: Option<Segmentation>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub amodal_bbox: Option<[u32; 4]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub amodal_area: Option<u64>,
    #[serde(flatten)]
    pub attributes: serde_json::Map<String, Value>,
}

impl Annotation {
    /// This frame-local annotation as image `image_id` of a dataset holds it: its id becomes the
    /// mask id, and the set-wide id is left for the merge.
    pub fn in_dataset(self, image_id: u64) -> Annotation {
        Annotation { mask_id: self.id, id: None, image_id, ..self }
    }

    /// As a JSON object with its keys sorted: the order a dataset's records and merged
    /// annotations.json have always had.
    pub fn sorted_json(&self) -> Value {
        serde_json::to_value(self).expect("COCO structures always serialise")
    }
}

/// Keypoints as COCO writes them: x and y as numbers, v as an integer, an unlabelled one 0, 0, 0.
fn serialize_keypoints<S: serde::Serializer>(keypoints: &Option<Vec<f64>>, s: S) -> Result<S::Ok, S::Error> {
    let flat = keypoints.as_deref().unwrap_or_default();
    s.collect_seq(flat.chunks(3).flat_map(|p| match p {
        [x, y, v] if *v > 0.0 => [json!(x), json!(y), json!(*v as u8)],
        _ => [json!(0), json!(0), json!(0)],
    }))
}

/// Serialises a list of annotations with sorted keys (see [`Annotation::sorted_json`]).
pub fn serialize_sorted<S: serde::Serializer>(annotations: &[Annotation], s: S) -> Result<S::Ok, S::Error> {
    s.collect_seq(annotations.iter().map(Annotation::sorted_json))
}

/// The annotations of `frame`, id k for the instance with id k in the mask, image id 1.
pub fn annotations(frame: &Frame, masks: &[InstanceMask]) -> Vec<Annotation> {
    let (w, h) = (frame.width, frame.height);
    masks
        .iter()
        .zip(&frame.instances)
        .enumerate()
        .map(|(k, (mask, instance))| {
            let amodal = instance.amodal.as_ref().map(|m| {
                let pixels = m.to_image(w, h);
                let rle = Rle::from_labels(
                    &pixels,
                    w,
                    h,
                    true,
                    PixelBox { x0: m.x0, y0: m.y0, x1: m.x0 + m.width - 1, y1: m.y0 + m.height - 1 },
                );
                (Segmentation { size: [h, w], counts: rle.to_coco_string() }, rle.area())
            });
            let keypoints = &instance.keypoints;
            Annotation {
                id: Some(k as u64 + 1),
                image_id: 1,
                category_id: instance.category_id,
                segmentation: Segmentation { size: [h, w], counts: mask.rle.to_coco_string() },
                area: mask.area,
                bbox: mask.bbox.to_xywh(),
                iscrowd: 0,
                mask_id: None,
                keypoints: (!keypoints.is_empty())
                    .then(|| keypoints.iter().flat_map(|p| [hundredth(p.x), hundredth(p.y), p.v as f64]).collect()),
                num_keypoints: (!keypoints.is_empty()).then(|| keypoints.iter().filter(|p| p.v > 0).count() as u32),
                amodal_bbox: instance.amodal.as_ref().map(|m| [m.x0, m.y0, m.width, m.height]),
                amodal_area: amodal.as_ref().map(|(_, area)| *area),
                amodal_segmentation: amodal.map(|(s, _)| s),
                attributes: instance.attributes.clone(),
            }
        })
        .collect()
}

/// A keypoint coordinate as written: to 1/100 pixel.
fn hundredth(c: f64) -> f64 {
    (c * 100.0).round() / 100.0
}

/// The procedural bed's one category.
pub fn mushroom_category() -> Category {
    Category::new(MUSHROOM, "mushroom", "mushroom")
}

/// annotations.json for `frame`, whose masks are `masks` and whose instances belong to
/// `categories`; `info` records where it came from.
pub fn coco_json(frame: &Frame, masks: &[InstanceMask], categories: &[Category], info: Value) -> String {
    let (w, h) = (frame.width, frame.height);
    let file = CocoFile {
        info,
        images: [Image { id: 1, file_name: IMAGE_FILE, width: w, height: h }],
        annotations: annotations(frame, masks),
        categories,
        licenses: [],
    };
    let mut text = serde_json::to_string(&file).expect("COCO structures always serialise");
    text.push('\n');
    text
}
