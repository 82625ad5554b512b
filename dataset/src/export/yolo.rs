//! Ultralytics' YOLO segmentation layout: `images/{split}/NAME.png`, `labels/{split}/NAME.txt`
//! (a line `class x1 y1 x2 y2 …` per instance, coordinates normalised to the image) and a
//! `data.yaml` without `path`, so Ultralytics takes the folder the file is in and OUT can move.
//! The folders and data.yaml are shared with the pose labels (`yolo_pose.rs`).

use super::polygons::MaskWindow;
use super::set::FinishedSet;
use super::splits::Split;
use super::staging::Staging;
use super::{stem, PolygonFit};
use crate::error::{Error, Result};
use serde_json::Value;
use std::fmt::Write as _;
use vkdiff_render::rle::Rle;

/// Simplify a polygon while its IoU with the mask stays this high (each instance falls back to
/// its exact outline where no simplification does).
const MIN_IOU: f64 = 0.95;

pub fn write(set: &FinishedSet, staging: &mut Staging, progress: &mut dyn FnMut(usize, usize)) -> Result<PolygonFit> {
    let mut fit = PolygonFit { instances: 0, min_iou: 1.0, mean_iou: 0.0, points: 0 };
    let mut line = |annotation: &Value, class: usize, width: f64, height: f64| -> Result<Option<String>> {
        let (polygon, iou) = mask_window(annotation)?.polygon(MIN_IOU);
        if polygon.is_empty() {
            return Ok(None);
        }
        fit.instances += 1;
        fit.points += polygon.len() as u64;
        fit.min_iou = fit.min_iou.min(iou);
        fit.mean_iou += iou;
        let mut text = format!("{class}");
        for [x, y] in polygon {
            write!(text, " {} {}", coordinate(x / width), coordinate(y / height)).expect("strings take writes");
        }
        Ok(Some(text))
    };
    write_layout(set, staging, progress, &Layout { task: "segmentation", extra_yaml: String::new() }, &mut line)?;
    fit.mean_iou /= fit.instances.max(1) as f64;
    Ok(fit)
}

/// What a YOLO layout's data.yaml says beyond the splits and names.
pub struct Layout {
    /// The labels' kind, for the file's heading.
    pub task: &'static str,
    /// More keys (pose: kpt_shape), each line ending in a newline.
    pub extra_yaml: String,
}

/// A label line of an annotation, given its class and the image's width and height; None skips it.
pub type LabelLine<'a> = dyn FnMut(&Value, usize, f64, f64) -> Result<Option<String>> + 'a;

/// Writes Ultralytics' folders and data.yaml: each image linked, each label file a `line` per
/// annotation.
pub fn write_layout(
    set: &FinishedSet,
    staging: &mut Staging,
    progress: &mut dyn FnMut(usize, usize),
    layout: &Layout,
    line: &mut LabelLine,
) -> Result<()> {
    let classes: Vec<u64> =
        set.categories.as_array().map_or(Vec::new(), |c| c.iter().filter_map(|c| c["id"].as_u64()).collect());
    for split in set.splits() {
        staging.folder(&format!("images/{}", split.name()))?;
        staging.folder(&format!("labels/{}", split.name()))?;
    }
    for (done, image) in set.images.iter().enumerate() {
        let (name, split) = (image.file_name(), image.split.name());
        let (width, height) =
            (image.entry["width"].as_f64().unwrap_or(0.0), image.entry["height"].as_f64().unwrap_or(0.0));
        let extension = name.rsplit('.').next().unwrap_or("png");
        staging.link(&set.dir.join(name), &format!("images/{split}/{}.{extension}", stem(name)))?;
        let mut labels = String::new();
        for annotation in &image.annotations {
            let class =
                classes.iter().position(|&c| Some(c) == annotation["category_id"].as_u64()).ok_or_else(|| {
                    Error::Config(format!(
                        "annotation {}: category {} is not in the file's categories",
                        annotation["id"], annotation["category_id"]
                    ))
                })?;
            if let Some(text) = line(annotation, class, width, height)? {
                labels.push_str(&text);
                labels.push('\n');
            }
        }
        staging.write(&format!("labels/{split}/{}.txt", stem(name)), labels.as_bytes())?;
        progress(done + 1, set.images.len());
    }
    staging.write("data.yaml", data_yaml(set, layout).as_bytes())
}

/// At most 6 decimals, no trailing zeros, within [0, 1].
pub fn coordinate(v: f64) -> String {
    let text = format!("{:.6}", v.clamp(0.0, 1.0));
    text.trim_end_matches('0').trim_end_matches('.').to_string()
}

fn data_yaml(set: &FinishedSet, layout: &Layout) -> String {
    let mut yaml = format!(
        "# YOLO {} labels exported by vkdiff {} from a vkdiff dataset, split by scene\n\
         # (val fraction {}, test fraction {}, seed {}). Ultralytics takes this file's folder as the root.\n",
        layout.task,
        vkdiff_setting::version(),
        set.fractions.val,
        set.fractions.test,
        set.fractions.seed
    );
    for split in Split::ALL {
        let name = split.name();
        if set.in_split(split).next().is_some() {
            let _ = writeln!(yaml, "{name}: images/{name}");
        } else if split == Split::Val {
            // Ultralytics refuses a dataset without val: with --val-fraction 0 (or a one-scene
            // set) it validates on train, and says so here.
            let _ = writeln!(yaml, "# no scene is in val: Ultralytics validates on train\nval: images/train");
        } else if split == Split::Train {
            // Nor does it take one without train: where every scene fell in val, it trains there.
            let _ = writeln!(yaml, "# no scene is in train: Ultralytics trains on val\ntrain: images/val");
        }
    }
    yaml.push_str("names:\n");
    for (k, category) in set.categories.as_array().into_iter().flatten().enumerate() {
        let _ = writeln!(yaml, "  {k}: {}", serde_json::to_string(&category["name"]).unwrap_or_default());
    }
    yaml + &layout.extra_yaml
}

/// The annotation's RLE mask over its bounding box.
fn mask_window(annotation: &Value) -> Result<MaskWindow> {
    let s = &annotation["segmentation"];
    let bad = || Error::Config(format!("annotation {}: its segmentation is not a COCO RLE mask", annotation["id"]));
    let (Some(counts), Some(h), Some(w)) = (s["counts"].as_str(), s["size"][0].as_u64(), s["size"][1].as_u64()) else {
        return Err(bad());
    };
    let rle = Rle::from_coco_string(counts, h as u32, w as u32).map_err(|_| bad())?;
    let Some(b) = rle.bbox() else {
        return Ok(MaskWindow { origin: [0, 0], width: 0, height: 0, pixels: Vec::new() });
    };
    let (width, height) = ((b.x1 - b.x0 + 1) as usize, (b.y1 - b.y0 + 1) as usize);
    let mut pixels = vec![false; width * height];
    let mut p = 0u64;
    for (i, &c) in rle.counts.iter().enumerate() {
        if i % 2 == 1 {
            for q in p..p + c as u64 {
                let (x, y) = ((q / h) as usize - b.x0 as usize, (q % h) as usize - b.y0 as usize);
                pixels[y * width + x] = true;
            }
        }
        p += c as u64;
    }
    Ok(MaskWindow { origin: [b.x0, b.y0], width, height, pixels })
}
