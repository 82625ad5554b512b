//! COCO ground truth (`images`, `annotations`, `categories`) and COCO results (a list of
//! detections), read as pycocotools' `COCO` and `loadRes` read them.

use crate::keypoints;
use crate::masks::{self, polygon_rle, union};
use crate::{EvalError, IouType, Result};
use serde_json::Value;
use std::collections::HashMap;
use vkdiff_render::rle::Rle;
use vkdiff_setting::Message;

/// What an annotation outlines.
#[derive(Clone, Debug)]
pub enum Geometry {
    Mask(Rle),
    /// Results given only as boxes (bbox evaluation).
    Box,
}

#[derive(Clone, Debug)]
pub struct Annotation {
    pub id: u64,
    pub image_id: u64,
    pub category_id: u64,
    pub area: f64,
    pub bbox: [f64; 4],
    pub iscrowd: bool,
    /// Ground truth COCOeval leaves out: crowd regions, and in keypoint evaluation those with no
    /// labelled keypoint (`num_keypoints` 0).
    pub ignore: bool,
    /// Detections only (ground truth: 1).
    pub score: f64,
    pub geometry: Geometry,
    /// x, y, v triples (keypoint evaluation only; empty otherwise or where none are given).
    pub keypoints: Vec<f64>,
}

/// Which rule gives each detection its area (and so its small / medium / large range).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AreaRule {
    /// pycocotools' `loadRes`: decided by the first result's keys for all of them.
    LoadRes,
    /// The mask's area whatever box a result carries: Detectron2's `COCOEvaluator`, which
    /// deletes `bbox` from its results before segm evaluation.
    Mask,
}

/// Where the detections' areas come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AreaSource {
    /// w·h of each `bbox`.
    Box,
    /// The area of each `segmentation`.
    Mask,
    /// The box around each result's keypoints (loadRes when results have neither box nor mask).
    Keypoints,
}

impl AreaSource {
    /// `loadRes`'s choice: boxes when the first result has a non-empty `bbox`, masks when it has
    /// a `segmentation` (an empty list of results has neither, and nothing to measure).
    pub fn of_results(json: &Value, rule: AreaRule) -> Result<AreaSource> {
        let first = match json.as_array().and_then(|l| l.first()) {
            Some(first) if rule == AreaRule::LoadRes => first,
            _ => return Ok(AreaSource::Mask),
        };
        if first.get("bbox").is_some_and(|b| b.as_array().is_none_or(|b| !b.is_empty())) {
            Ok(AreaSource::Box)
        } else if first.get("segmentation").is_some() {
            Ok(AreaSource::Mask)
        } else if first.get("keypoints").is_some() {
            Ok(AreaSource::Keypoints)
        } else {
            Err(err("results[0] has no `bbox`, `segmentation` or `keypoints`".into()))
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            AreaSource::Box => "box",
            AreaSource::Mask => "mask",
            AreaSource::Keypoints => "keypoints' box",
        }
    }
}

/// Images (id → height, width) and their annotations, in file order.
#[derive(Clone, Debug, Default)]
pub struct Dataset {
    pub images: HashMap<u64, (u32, u32)>,
    pub categories: Vec<u64>,
    /// The ground truth's category names, by id.
    pub category_names: HashMap<u64, String>,
    pub annotations: Vec<Annotation>,
}

pub(crate) fn err(what: String) -> EvalError {
    EvalError::Invalid(what)
}

pub(crate) fn number(v: &Value, what: &str) -> Result<f64> {
    v.as_f64().ok_or_else(|| err(format!("{what} is not a number: {}", short(v))))
}

fn id(v: &Value, what: &str) -> Result<u64> {
    v.as_u64().ok_or_else(|| err(format!("{what} is not a non-negative integer: {}", short(v))))
}

fn short(v: &Value) -> String {
    let s = v.to_string();
    if s.len() > 60 {
        format!("{}…", &s[..s.char_indices().nth(60).map_or(s.len(), |(i, _)| i)])
    } else {
        s
    }
}

pub(crate) fn field<'a>(o: &'a Value, key: &str, what: &str) -> Result<&'a Value> {
    o.get(key).ok_or_else(|| err(format!("{what} has no `{key}`")))
}

/// A segmentation (polygons, uncompressed or compressed RLE) as one mask of the image's size.
fn segmentation(v: &Value, (h, w): (u32, u32), what: &str) -> Result<Rle> {
    match v {
        Value::Array(polys) => {
            let rles = polys
                .iter()
                .map(|p| {
                    let xy = p.as_array().ok_or_else(|| err(format!("{what}: a polygon is not a list of numbers")))?;
                    let xy: Vec<f64> = xy.iter().map(|c| number(c, what)).collect::<Result<_>>()?;
                    Ok(polygon_rle(&xy, h, w))
                })
                .collect::<Result<Vec<_>>>()?;
            Ok(union(&rles, h, w))
        }
        Value::Object(o) => {
            let size =
                o.get("size").and_then(Value::as_array).ok_or_else(|| err(format!("{what}: an RLE without `size`")))?;
            let (rh, rw) = match size.as_slice() {
                [a, b] => (id(a, what)? as u32, id(b, what)? as u32),
                _ => return Err(err(format!("{what}: RLE `size` is not [height, width]"))),
            };
            if (rh, rw) != (h, w) {
                return Err(err(format!("{what}: RLE of size {rh}×{rw} on an image of {h}×{w}")));
            }
            match o.get("counts") {
                Some(Value::String(s)) => Rle::from_coco_string(s, h, w).map_err(|e| err(format!("{what}: {e}"))),
                Some(Value::Array(c)) => {
                    let counts: Vec<u32> = c.iter().map(|x| id(x, what).map(|x| x as u32)).collect::<Result<_>>()?;
                    let total: u64 = counts.iter().map(|&c| c as u64).sum();
                    if total != h as u64 * w as u64 {
                        return Err(err(format!("{what}: RLE counts cover {total} pixels, not {h}×{w}")));
                    }
                    Ok(Rle { height: h, width: w, counts })
                }
                _ => Err(err(format!("{what}: RLE `counts` is neither a string nor a list"))),
            }
        }
        _ => Err(err(format!("{what}: `segmentation` is neither polygons nor an RLE"))),
    }
}

fn bbox(v: &Value, what: &str) -> Result<[f64; 4]> {
    let b = v.as_array().filter(|b| b.len() == 4).ok_or_else(|| err(format!("{what}: `bbox` is not [x, y, w, h]")))?;
    Ok([number(&b[0], what)?, number(&b[1], what)?, number(&b[2], what)?, number(&b[3], what)?])
}

impl Dataset {
    /// The images' ids, ascending (pycocotools' `imgIds`).
    pub fn image_ids(&self) -> Vec<u64> {
        let mut images: Vec<u64> = self.images.keys().copied().collect();
        images.sort_unstable();
        images
    }

    /// The categories' ids, ascending (pycocotools' `catIds`): those listed, else those the
    /// annotations name.
    pub fn category_ids(&self) -> Vec<u64> {
        let mut cats = self.categories.clone();
        if cats.is_empty() {
            cats = self.annotations.iter().map(|a| a.category_id).collect();
        }
        cats.sort_unstable();
        cats.dedup();
        cats
    }

    /// COCO ground truth. Masks are decoded only for segm evaluation, keypoints only for
    /// keypoint evaluation.
    pub fn ground_truth(json: &Value, iou_type: IouType) -> Result<Dataset> {
        let masks = iou_type == IouType::Segm;
        let mut d = Dataset::default();
        for (i, img) in json
            .get("images")
            .and_then(Value::as_array)
            .ok_or_else(|| err("ground truth has no `images` list".into()))?
            .iter()
            .enumerate()
        {
            let what = format!("images[{i}]");
            let size =
                (id(field(img, "height", &what)?, &what)? as u32, id(field(img, "width", &what)?, &what)? as u32);
            d.images.insert(id(field(img, "id", &what)?, &what)?, size);
        }
        if let Some(cats) = json.get("categories").and_then(Value::as_array) {
            d.categories = cats
                .iter()
                .enumerate()
                .map(|(i, c)| id(field(c, "id", &format!("categories[{i}]"))?, "category id"))
                .collect::<Result<_>>()?;
            for (c, &k) in cats.iter().zip(&d.categories) {
                d.category_names.insert(k, c.get("name").and_then(Value::as_str).unwrap_or_default().to_string());
            }
        }
        for (i, a) in json
            .get("annotations")
            .and_then(Value::as_array)
            .ok_or_else(|| err("ground truth has no `annotations` list".into()))?
            .iter()
            .enumerate()
        {
            let what = format!("annotations[{i}]");
            let image_id = id(field(a, "image_id", &what)?, &what)?;
            let size =
                *d.images.get(&image_id).ok_or_else(|| err(format!("{what}: image {image_id} is not in `images`")))?;
            let geometry = if masks {
                Geometry::Mask(segmentation(field(a, "segmentation", &what)?, size, &what)?)
            } else {
                Geometry::Box
            };
            let bbox = match a.get("bbox") {
                Some(b) => bbox(b, &what)?,
                None => match &geometry {
                    Geometry::Mask(r) => masks::bbox(r),
                    Geometry::Box => return Err(err(format!("{what} has no `bbox`"))),
                },
            };
            let iscrowd = a.get("iscrowd").and_then(Value::as_u64).unwrap_or(0) != 0;
            let (keypoints, labelled) = match iou_type {
                IouType::Keypoints => keypoints::ground_truth(a, &what)?,
                _ => (Vec::new(), 0),
            };
            d.annotations.push(Annotation {
                id: id(field(a, "id", &what)?, &what)?,
                image_id,
                category_id: id(field(a, "category_id", &what)?, &what)?,
                area: number(field(a, "area", &what)?, &what)?,
                bbox,
                iscrowd,
                ignore: iscrowd || (iou_type == IouType::Keypoints && labelled == 0),
                score: 1.0,
                geometry,
                keypoints,
            });
        }
        Ok(d)
    }

    /// Results name their categories by the ground truth's ids: a result whose category the
    /// ground truth does not list scores against nothing, so it is refused, naming both sets.
    fn check_categories(&self, gt: &Dataset) -> Result<()> {
        if gt.categories.is_empty() {
            return Ok(());
        }
        let Some(stray) = self.annotations.iter().map(|a| a.category_id).find(|c| !gt.categories.contains(c)) else {
            return Ok(());
        };
        let count = self.annotations.iter().filter(|a| a.category_id == stray).count();
        let listed: Vec<String> = gt
            .categories
            .iter()
            .map(|c| format!("{c} ({})", gt.category_names.get(c).map_or("", String::as_str)))
            .collect();
        Err(err(format!(
            "{count} results have category {stray}, which the ground truth does not list (its categories: {}); \
             results name categories by the ground truth's ids",
            listed.join(", ")
        )))
    }

    /// COCO results on the images of `gt`, as `loadRes` reads them: ids 1, 2, … in file order,
    /// not crowd; with areas from boxes, each w·h, or from masks, and a result's missing mask the
    /// polygon of its box (box areas) or its missing box the mask's (mask areas); in keypoint
    /// evaluation each result's keypoints, its area and box those of the keypoints where it has
    /// neither box nor mask.
    pub fn results(json: &Value, gt: &Dataset, iou_type: IouType, areas: AreaSource) -> Result<Dataset> {
        let masks = iou_type == IouType::Segm;
        let list = json.as_array().ok_or_else(|| err("results are not a JSON list of detections".into()))?;
        let mut d = Dataset {
            images: gt.images.clone(),
            categories: gt.categories.clone(),
            category_names: gt.category_names.clone(),
            annotations: Vec::new(),
        };
        for (i, a) in list.iter().enumerate() {
            let what = format!("results[{i}]");
            let image_id = id(field(a, "image_id", &what)?, &what)?;
            let size = *gt
                .images
                .get(&image_id)
                .ok_or_else(|| err(format!("{what}: image {image_id} is not in the ground truth")))?;
            let (geometry, area, bbox) = match areas {
                AreaSource::Box => {
                    let b = a.get("bbox").ok_or_else(|| {
                        EvalError::Setting(
                            Message::text(format!(
                                "{what} has no `bbox`, but results[0] has one: pycocotools' loadRes reads every \
                                result by the first one's keys (give every result a box, or pass "
                            ))
                            .and("area_from")
                            .then(" mask)"),
                        )
                    })?;
                    let b = bbox(b, &what)?;
                    let geometry = match (masks, a.get("segmentation")) {
                        (false, _) => Geometry::Box,
                        (true, Some(s)) => Geometry::Mask(segmentation(s, size, &what)?),
                        (true, None) => {
                            let (x1, y1, x2, y2) = (b[0], b[1], b[0] + b[2], b[1] + b[3]);
                            Geometry::Mask(polygon_rle(&[x1, y1, x1, y2, x2, y2, x2, y1], size.0, size.1))
                        }
                    };
                    (geometry, b[2] * b[3], b)
                }
                AreaSource::Mask => {
                    let rle = segmentation(field(a, "segmentation", &what)?, size, &what)?;
                    let area = masks::runs_area(&masks::ones(&rle)) as f64;
                    let b = match a.get("bbox").filter(|b| b.as_array().is_some_and(|b| !b.is_empty())) {
                        Some(b) => bbox(b, &what)?,
                        None => masks::bbox(&rle),
                    };
                    (if masks { Geometry::Mask(rle) } else { Geometry::Box }, area, b)
                }
                AreaSource::Keypoints => {
                    let (area, b) = keypoints::extent(&keypoints::result(a, &what)?);
                    (Geometry::Box, area, b)
                }
            };
            let keypoints = match iou_type {
                IouType::Keypoints => keypoints::result(a, &what)?,
                _ => Vec::new(),
            };
            d.annotations.push(Annotation {
                id: i as u64 + 1,
                image_id,
                category_id: id(field(a, "category_id", &what)?, &what)?,
                area,
                bbox,
                iscrowd: false,
                ignore: false,
                score: number(field(a, "score", &what)?, &what)?,
                geometry,
                keypoints,
            });
        }
        d.check_categories(gt)?;
        Ok(d)
    }
}
