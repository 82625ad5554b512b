//! The prediction files `vkdiff dataset audit` reads, each turned into COCO results on the set's
//! own image and category ids: COCO results (Detectron2, MMDetection), Ultralytics' `predict`
//! labels (`save_txt=True, save_conf=True`: a folder of `STEM.txt`, a line `class x y w h conf`
//! or `class x1 y1 … xn yn conf` per object, normalised to the image) and Ultralytics' JSON
//! (`val(save_json=True)`'s `predictions.json`: image ids from the file stems, category ids its
//! class + 1). Ultralytics names images by their stems and classes by data.yaml's order, which
//! `dataset export --format yolo` takes from the set's categories.

use crate::error::{Error, Result};
use serde_json::{json, Value};
use std::collections::HashMap;
use std::path::Path;
use vkdiff_formats::Error as FileError;

/// How a predictions file is laid out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PredictionFormat {
    Coco,
    UltralyticsTxt,
    UltralyticsJson,
}

impl PredictionFormat {
    pub fn name(self) -> &'static str {
        match self {
            PredictionFormat::Coco => "coco",
            PredictionFormat::UltralyticsTxt => "ultralytics-txt",
            PredictionFormat::UltralyticsJson => "ultralytics-json",
        }
    }
}

/// The set's images by file stem (id, width, height) and its category ids in order.
pub struct SetIndex {
    pub by_stem: HashMap<String, (u64, u32, u32)>,
    pub categories: Vec<u64>,
}

fn stem(name: &str) -> String {
    Path::new(name).file_stem().map_or_else(String::new, |s| s.to_string_lossy().into_owned())
}

impl SetIndex {
    /// `annotations.json`'s images and categories.
    pub fn of(coco: &Value) -> SetIndex {
        let by_stem = coco["images"]
            .as_array()
            .into_iter()
            .flatten()
            .filter_map(|i| {
                let size = (i["width"].as_u64()? as u32, i["height"].as_u64()? as u32);
                Some((stem(i["file_name"].as_str()?), (i["id"].as_u64()?, size.0, size.1)))
            })
            .collect();
        let categories = coco["categories"].as_array().into_iter().flatten().filter_map(|c| c["id"].as_u64()).collect();
        SetIndex { by_stem, categories }
    }

    fn image(&self, stem: &str, what: &dyn Fn() -> String) -> Result<(u64, u32, u32)> {
        self.by_stem.get(stem).copied().ok_or_else(|| Error::Config(format!("{}: no image {stem} in the set", what())))
    }

    fn category(&self, class: u64, what: &dyn Fn() -> String) -> Result<u64> {
        self.categories.get(class as usize).copied().ok_or_else(|| {
            Error::Config(format!("{}: class {class}, but the set has {} categories", what(), self.categories.len()))
        })
    }
}

/// The predictions at `path` as COCO results on the set's ids, and the format they were in
/// (`format`, else told by what `path` is: a folder of labels, or JSON whose entries name their
/// images by file, which Ultralytics' does and COCO results do not).
pub fn read_predictions(
    path: &Path,
    format: Option<PredictionFormat>,
    set: &SetIndex,
) -> Result<(Value, PredictionFormat)> {
    if path.is_dir() || format == Some(PredictionFormat::UltralyticsTxt) {
        return Ok((ultralytics_labels(path, set)?, PredictionFormat::UltralyticsTxt));
    }
    let text = std::fs::read(path).map_err(|e| FileError::Io { path: path.to_path_buf(), source: e })?;
    let json: Value = serde_json::from_slice(&text)
        .map_err(|e| FileError::Format { path: path.to_path_buf(), why: format!("not JSON: {e}") })?;
    let list = json
        .as_array()
        .ok_or_else(|| Error::Config(format!("{}: not a results list (a JSON list of detections)", path.display())))?;
    let ultralytics = list.iter().any(|r| r.get("file_name").is_some() || r["image_id"].is_string());
    match format.unwrap_or(if ultralytics { PredictionFormat::UltralyticsJson } else { PredictionFormat::Coco }) {
        PredictionFormat::UltralyticsJson => {
            Ok((ultralytics_json(path, list, set)?, PredictionFormat::UltralyticsJson))
        }
        _ => Ok((json, PredictionFormat::Coco)),
    }
}

/// Ultralytics' JSON: each entry's image from its `file_name` (else its `image_id`, the stem,
/// an integer where the stem is one), its category from `category_id` − 1 (a class index).
fn ultralytics_json(path: &Path, list: &[Value], set: &SetIndex) -> Result<Value> {
    let numeric: HashMap<u64, &str> =
        set.by_stem.keys().filter_map(|s| Some((s.parse::<u64>().ok()?, s.as_str()))).collect();
    let mut out = Vec::with_capacity(list.len());
    for (k, r) in list.iter().enumerate() {
        let what = || format!("{}: entry {k}", path.display());
        let name = match (&r["file_name"], &r["image_id"]) {
            (Value::String(f), _) => stem(f),
            (_, Value::String(s)) => s.clone(),
            (_, Value::Number(n)) => {
                let n = n.as_u64().ok_or_else(|| Error::Config(format!("{}: image_id {n}", what())))?;
                numeric.get(&n).map_or_else(|| n.to_string(), |s| s.to_string())
            }
            _ => return Err(Error::Config(format!("{}: no file_name or image_id", what()))),
        };
        let (image_id, ..) = set.image(&name, &what)?;
        let class = r["category_id"]
            .as_u64()
            .and_then(|c| c.checked_sub(1))
            .ok_or_else(|| Error::Config(format!("{}: category_id is not a class + 1", what())))?;
        let mut entry = r.clone();
        entry["image_id"] = image_id.into();
        entry["category_id"] = set.category(class, &what)?.into();
        if let Some(o) = entry.as_object_mut() {
            o.remove("file_name");
        }
        out.push(entry);
    }
    Ok(Value::Array(out))
}

/// Ultralytics' `predict` labels: `STEM.txt` files (in `dir` or its `labels/`), with confidences.
fn ultralytics_labels(dir: &Path, set: &SetIndex) -> Result<Value> {
    let folder = if dir.join("labels").is_dir() { dir.join("labels") } else { dir.to_path_buf() };
    let listing = std::fs::read_dir(&folder).map_err(|e| FileError::Io { path: folder.clone(), source: e })?;
    let mut files: Vec<_> =
        listing.flatten().map(|e| e.path()).filter(|p| p.extension().is_some_and(|x| x == "txt")).collect();
    files.sort();
    if files.is_empty() {
        return Err(Error::Config(format!(
            "{}: no .txt labels (Ultralytics' predict with save_txt=True)",
            folder.display()
        )));
    }
    let mut out = Vec::new();
    for file in &files {
        let text = std::fs::read_to_string(file).map_err(|e| FileError::Io { path: file.clone(), source: e })?;
        let (image_id, w, h) = set.image(&stem(&file.to_string_lossy()), &|| file.display().to_string())?;
        for (n, line) in text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
            let what = || format!("{} line {}", file.display(), n + 1);
            let v: Vec<f64> = line
                .split_whitespace()
                .map(|x| x.parse::<f64>().map_err(|_| Error::Config(format!("{}: {x:?} is not a number", what()))))
                .collect::<Result<_>>()?;
            // class, a box (4) or a polygon (6 or more, even), the confidence.
            if v.len() < 6 || !v.len().is_multiple_of(2) {
                return Err(Error::Config(format!(
                    "{}: {} numbers, not a class, a box or polygon and a confidence (predict with save_conf=True)",
                    what(),
                    v.len()
                )));
            }
            let category = set.category(v[0] as u64, &what)?;
            let (w, h) = (w as f64, h as f64);
            let score = v[v.len() - 1];
            let coords = &v[1..v.len() - 1];
            out.push(if coords.len() == 4 {
                let (bw, bh) = (coords[2] * w, coords[3] * h);
                json!({"image_id": image_id, "category_id": category, "score": score,
                       "bbox": [coords[0] * w - bw / 2.0, coords[1] * h - bh / 2.0, bw, bh]})
            } else {
                let xy: Vec<f64> = coords.chunks(2).flat_map(|p| [p[0] * w, p[1] * h]).collect();
                let (xs, ys) = (xy.iter().step_by(2), xy.iter().skip(1).step_by(2));
                let (x0, x1) =
                    (xs.clone().copied().fold(f64::INFINITY, f64::min), xs.copied().fold(f64::NEG_INFINITY, f64::max));
                let (y0, y1) =
                    (ys.clone().copied().fold(f64::INFINITY, f64::min), ys.copied().fold(f64::NEG_INFINITY, f64::max));
                json!({"image_id": image_id, "category_id": category, "score": score,
                       "segmentation": [xy], "bbox": [x0, y0, x1 - x0, y1 - y0]})
            });
        }
    }
    Ok(Value::Array(out))
}
