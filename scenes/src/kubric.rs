//! Kubric's output folders (google-research/kubric at 0ee21e2a; PyPI's kubric-nightly
//! 2023.12.27), as its workers write them (challenges/movi/movi_def_worker.py: kb.write_image_dict,
//! then kb.write_json of metadata.json, through kubric/file_io.py):
//!
//! ```text
//! SEQ/rgba_NNNNN.png           the render, 8-bit RGBA (write_png; alpha dropped)
//! SEQ/depth_NNNNN.tiff         float32 H×W×1 (write_tiff: imageio → tifffile, uncompressed):
//!                              the distance along the ray (process_depth); 1e10·… where nothing is hit
//! SEQ/segmentation_NNNNN.png   8-bit palette PNG (write_palette_png): per pixel the instance's index,
//!                              k ↔ metadata.json's instances[k − 1] (adjust_segmentation_idxs); 0 background
//! SEQ/normal_NNNNN.png         optional: 16-bit RGB, world-space normals (n + 1)·65535/2
//! SEQ/metadata.json            written after every frame's images: "metadata" (resolution [W, H],
//!                              num_frames), "camera" (K, positions, quaternions per frame, …),
//!                              "instances" (asset_id, category, positions, quaternions, bboxes_3d …)
//! SEQ/events.json, data_ranges.json (with flows), other layers   not read
//! ```
//!
//! Frame f of a sequence (its files numbered f from 00000, the metadata's arrays' index f) is one
//! scene, named `<seq>/<NNNNN>` (the folder's name), in sequence (name) then frame order;
//! `--scenes` is one sequence folder or a folder of them. A sequence folder whose frames are
//! written but whose metadata.json is not (a run stopped, or still writing) is skipped with a note.
//! metadata.json is parsed once, when the folder is opened (kubric_metadata.rs); the frames'
//! headers are checked when the scenes are listed.
//!
//! Instances: segmentation index k is instance k, its annotation carrying `instance_id` k and its
//! `asset_id`; an index past the instances listed stops the scene, naming the pixel. Categories:
//! a categories.json beside the sequences (its names are the instances' category names), else
//! ids 1, 2, … in name order over every sequence; an instance's category name is its `category`
//! (Google Scanned Objects' manifest metadata), else its `asset_id` (KuBasic's "cube", …), else
//! `--category`. Depth: the TIFF made planar with K. Camera: K from `camera.K`, pose from the
//! frame's `positions` and `quaternions`; pose and 3D box from each instance's, where it has
//! them (kubric_geometry.rs has the conventions). Normals: normal_NNNNN.png, turned into the
//! camera's frame.

use crate::format::{SceneFormat, SceneIndex};
use crate::kubric_geometry::{decode_normal, planar_from_distance};
use crate::kubric_metadata::{name_of, parse_sequence, Sequence, METADATA};
use crate::labels::{read_categories, CategoryGuide, RawScene};
use crate::{bad, SceneError};
use rayon::prelude::*;
use serde_json::{json, Map};
use std::collections::{BTreeMap, BTreeSet};
use std::io::BufReader;
use std::path::{Path, PathBuf};
use vkdiff_formats::image::{image_size, read_image};
use vkdiff_render::camera::{Camera, Pose};
use vkdiff_render::coco::Category;

/// `<prefix>NNNNN<suffix>` → NNNNN (five digits or more, as `{:05d}` writes them).
fn frame_number(name: &str, prefix: &str, suffix: &str) -> Option<usize> {
    let n = name.strip_prefix(prefix)?.strip_suffix(suffix)?;
    (n.len() >= 5 && n.bytes().all(|b| b.is_ascii_digit())).then(|| n.parse().ok())?
}

fn file(kind: &str, frame: usize) -> String {
    match kind {
        "depth" => format!("depth_{frame:05}.tiff"),
        _ => format!("{kind}_{frame:05}.png"),
    }
}

/// A folder holding Kubric frames: a segmentation_NNNNN.png or depth_NNNNN.tiff.
fn has_frames(path: &Path) -> bool {
    std::fs::read_dir(path).is_ok_and(|entries| {
        entries.flatten().any(|e| {
            let name = e.file_name();
            let name = name.to_string_lossy();
            frame_number(&name, "segmentation_", ".png").is_some() || frame_number(&name, "depth_", ".tiff").is_some()
        })
    })
}

/// Kubric sequences, every metadata.json parsed.
#[derive(Debug)]
pub struct KubricSequences {
    sequences: Vec<Sequence>,
    /// Scene key (the sequence folder joined with the frame's number) → (sequence, frame).
    scenes: BTreeMap<PathBuf, (usize, usize)>,
    /// Category name → category.
    categories: BTreeMap<String, Category>,
    guides: BTreeMap<u32, CategoryGuide>,
    notes: Vec<String>,
}

impl KubricSequences {
    /// The sequence folders among `paths` (a folder's entries), in name order, or `dir` itself
    /// where it holds Kubric frames; None where there is none.
    pub fn find(dir: &Path, paths: &[PathBuf]) -> Option<Vec<PathBuf>> {
        if has_frames(dir) {
            return Some(vec![dir.to_path_buf()]);
        }
        let found: Vec<PathBuf> = paths.iter().filter(|p| p.is_dir() && has_frames(p)).cloned().collect();
        (!found.is_empty()).then_some(found)
    }

    /// Parses each sequence's metadata.json, and categories.json in `dir`; the scenes' keys, in
    /// order. A sequence without its metadata.json is left out with a note (refused where it is
    /// the only one). `default_category` names instances with neither a category nor an asset_id.
    pub fn open(
        dir: &Path,
        folders: &[PathBuf],
        default_category: &str,
    ) -> Result<(KubricSequences, Vec<PathBuf>), SceneError> {
        let mut notes = Vec::new();
        let mut written = Vec::new();
        for folder in folders {
            if folder.join(METADATA).is_file() {
                written.push(folder.clone());
            } else {
                notes.push(format!(
                    "{} skipped: {METADATA} is not written (Kubric writes it after every frame's images: a run stopped, \
                     or still writing)",
                    name_of(folder)
                ));
            }
        }
        if written.is_empty() {
            let names: Vec<String> = folders.iter().map(|f| name_of(f)).collect();
            return Err(SceneError::new(format!(
                "{}: {METADATA} missing; Kubric writes it after every frame's images (a run stopped, or still writing)",
                names.join(", ")
            )));
        }
        let sequences: Vec<Sequence> = written
            .par_iter()
            .map(|folder| parse_sequence(folder, default_category))
            .collect::<Result<_, SceneError>>()?;
        let mut scenes = BTreeMap::new();
        let mut keys = Vec::new();
        for (s, sequence) in sequences.iter().enumerate() {
            for f in 0..sequence.poses.len() {
                let key = sequence.folder.join(format!("{f:05}"));
                keys.push(key.clone());
                scenes.insert(key, (s, f));
            }
        }
        let used: BTreeSet<&str> =
            sequences.iter().flat_map(|s| s.instances.iter().map(|i| i.category.as_str())).collect();
        let boxed: BTreeSet<&str> = sequences
            .iter()
            .flat_map(|s| {
                s.instances.iter().filter(|i| i.boxes.iter().any(Option::is_some)).map(|i| i.category.as_str())
            })
            .collect();
        let path = dir.join("categories.json");
        let (categories, guides) = if path.is_file() {
            let (listed, _, guides) = read_categories(&path)?;
            let named: BTreeMap<String, Category> = listed.into_iter().map(|c| (c.name.clone(), c)).collect();
            if let Some(name) = used.iter().find(|n| !named.contains_key(**n)) {
                let why = format!("names no category `{name}`; its names are the instances' categories (or asset ids)");
                return Err(SceneError::file(&path, why));
            }
            (named, guides)
        } else {
            let numbered = used
                .iter()
                .enumerate()
                .map(|(k, name)| (name.to_string(), Category::new(k as u32 + 1, name, "object")));
            (numbered.collect(), BTreeMap::new())
        };
        let categories = categories
            .into_iter()
            .map(|(name, c)| {
                let c =
                    if boxed.contains(name.as_str()) && c.keypoints.is_empty() { c.with_box_keypoints() } else { c };
                (name, c)
            })
            .collect();
        Ok((KubricSequences { sequences, scenes, categories, guides, notes }, keys))
    }

    fn scene(&self, key: &Path) -> Result<(&Sequence, usize), SceneError> {
        let &(s, f) = self
            .scenes
            .get(key)
            .ok_or_else(|| SceneError::new(format!("{} is not a listed Kubric frame", key.display())))?;
        Ok((&self.sequences[s], f))
    }
}

fn open(folder: &Path, name: &str) -> Result<BufReader<std::fs::File>, SceneError> {
    std::fs::File::open(folder.join(name)).map(BufReader::new).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => bad(name, format!("missing ({METADATA} says the frame is there)")),
        _ => bad(name, e),
    })
}

/// The segmentation PNG's header: Kubric's 8-bit palette, or 8- or 16-bit grey.
fn segmentation_header(folder: &Path, name: &str) -> Result<png::Reader<BufReader<std::fs::File>>, SceneError> {
    let mut decoder = png::Decoder::new(open(folder, name)?);
    decoder.set_transformations(png::Transformations::IDENTITY);
    let reader = decoder.read_info().map_err(|e| bad(name, format!("bad PNG: {e}")))?;
    let info = reader.info();
    match (info.color_type, info.bit_depth) {
        (png::ColorType::Indexed, png::BitDepth::Eight)
        | (png::ColorType::Grayscale, png::BitDepth::Eight | png::BitDepth::Sixteen) => Ok(reader),
        (colour, depth) => {
            Err(bad(name, format!("{colour:?} {}-bit, not the 8-bit palette of indices Kubric writes", depth as u8)))
        }
    }
}

/// The depth TIFF's decoder, its size and sample type checked: float32, one sample.
fn depth_header(folder: &Path, name: &str) -> Result<tiff::decoder::Decoder<BufReader<std::fs::File>>, SceneError> {
    let tiff_error = |e: tiff::TiffError| bad(name, format!("bad TIFF: {e}"));
    let mut decoder = tiff::decoder::Decoder::new(open(folder, name)?).map_err(tiff_error)?;
    let colour = decoder.colortype().map_err(tiff_error)?;
    let format = decoder.find_tag_unsigned::<u16>(tiff::tags::Tag::SampleFormat).map_err(tiff_error)?;
    if colour != tiff::ColorType::Gray(32) || format != Some(3) {
        let kind = match format {
            Some(3) => "float",
            Some(2) => "signed",
            _ => "unsigned",
        };
        return Err(bad(name, format!("{colour:?} {kind}, not the one-channel float32 depth Kubric writes")));
    }
    Ok(decoder)
}

fn same_size(name: &str, size: (usize, usize), sequence: &Sequence) -> Result<(), SceneError> {
    let want = (sequence.width as usize, sequence.height as usize);
    if size == want {
        return Ok(());
    }
    Err(bad(name, format!("{}×{}, {METADATA}'s resolution is {}×{}", size.0, size.1, want.0, want.1)))
}

impl Sequence {
    /// Every file's size against the resolution, and what the headers hold.
    fn check(&self, frame: usize) -> Result<(), SceneError> {
        let segmentation = file("segmentation", frame);
        let reader = segmentation_header(&self.folder, &segmentation)?;
        let info = reader.info();
        same_size(&segmentation, (info.width as usize, info.height as usize), self)?;
        if info.bit_depth == png::BitDepth::Eight && self.instances.len() > 255 {
            return Err(bad(
                &segmentation,
                format!(
                    "8-bit, and {METADATA} lists {} instances: Kubric's palette PNG holds indices up to 255 (its \
                     write_palette_png wraps larger ones)",
                    self.instances.len()
                ),
            ));
        }
        let depth = file("depth", frame);
        let (w, h) =
            depth_header(&self.folder, &depth)?.dimensions().map_err(|e| bad(&depth, format!("bad TIFF: {e}")))?;
        same_size(&depth, (w as usize, h as usize), self)?;
        for kind in ["rgba", "normal"] {
            let name = file(kind, frame);
            let path = self.folder.join(&name);
            if path.exists() {
                let size = image_size(&path).map_err(|e| bad(&name, e))?;
                same_size(&name, size, self)?;
            }
        }
        Ok(())
    }

    fn depth(&self, frame: usize) -> Result<Vec<f32>, SceneError> {
        let name = file("depth", frame);
        let mut decoder = depth_header(&self.folder, &name)?;
        match decoder.read_image().map_err(|e| bad(&name, format!("bad TIFF: {e}")))? {
            tiff::decoder::DecodingResult::F32(mut depth) => {
                planar_from_distance(&mut depth, self.width as usize, self.k);
                Ok(depth)
            }
            _ => Err(bad(&name, "not float32")),
        }
    }

    fn labels(&self, frame: usize) -> Result<Vec<u32>, SceneError> {
        let name = file("segmentation", frame);
        let mut reader = segmentation_header(&self.folder, &name)?;
        let mut buf = vec![0; reader.output_buffer_size().unwrap_or(0)];
        let info = reader.next_frame(&mut buf).map_err(|e| bad(&name, format!("bad PNG: {e}")))?;
        let width = info.width as usize;
        let values: Vec<u32> = match info.bit_depth {
            png::BitDepth::Sixteen => {
                buf[..info.buffer_size()].chunks_exact(2).map(|b| u16::from_be_bytes([b[0], b[1]]) as u32).collect()
            }
            _ => buf[..info.buffer_size()].iter().map(|&v| v as u32).collect(),
        };
        if let Some(p) = values.iter().position(|&v| v as usize > self.instances.len()) {
            return Err(bad(
                &name,
                format!(
                    "pixel ({}, {}) is index {}; {METADATA} lists {} instances (index k is instances[k − 1], 0 \
                     background)",
                    p % width,
                    p / width,
                    values[p],
                    self.instances.len()
                ),
            ));
        }
        Ok(values)
    }

    fn normals(&self, frame: usize) -> Result<Option<Vec<[f32; 3]>>, SceneError> {
        let name = file("normal", frame);
        if !self.folder.join(&name).exists() {
            return Ok(None);
        }
        let mut decoder = png::Decoder::new(open(&self.folder, &name)?);
        decoder.set_transformations(png::Transformations::IDENTITY);
        let mut reader = decoder.read_info().map_err(|e| bad(&name, format!("bad PNG: {e}")))?;
        let (colour, depth) = (reader.info().color_type, reader.info().bit_depth);
        if colour != png::ColorType::Rgb || !matches!(depth, png::BitDepth::Eight | png::BitDepth::Sixteen) {
            return Err(bad(&name, format!("{colour:?} {}-bit, not the RGB normals Kubric writes", depth as u8)));
        }
        let mut buf = vec![0; reader.output_buffer_size().unwrap_or(0)];
        let info = reader.next_frame(&mut buf).map_err(|e| bad(&name, format!("bad PNG: {e}")))?;
        let camera = &self.poses[frame].1;
        let normals = match depth {
            png::BitDepth::Sixteen => buf[..info.buffer_size()]
                .chunks_exact(6)
                .map(|c| {
                    let v = |i: usize| u16::from_be_bytes([c[2 * i], c[2 * i + 1]]);
                    decode_normal([v(0), v(1), v(2)], 65535.0, camera)
                })
                .collect(),
            _ => buf[..info.buffer_size()]
                .chunks_exact(3)
                .map(|c| decode_normal([c[0], c[1], c[2]].map(u16::from), 255.0, camera))
                .collect(),
        };
        Ok(Some(normals))
    }
}

impl SceneFormat for KubricSequences {
    fn name(&self) -> &'static str {
        "kubric"
    }

    fn scene_name(&self, key: &Path) -> String {
        match self.scene(key) {
            Ok((sequence, frame)) => format!("{}/{frame:05}", sequence.name),
            Err(_) => key.display().to_string(),
        }
    }

    fn index(&self, key: &Path) -> Result<SceneIndex, SceneError> {
        let (sequence, frame) = self.scene(key)?;
        sequence.check(frame)?;
        let used: BTreeSet<&str> = sequence.instances.iter().map(|i| i.category.as_str()).collect();
        let mut categories: Vec<Category> = used.iter().map(|c| self.categories[*c].clone()).collect();
        categories.sort_by_key(|c| c.id);
        Ok(SceneIndex {
            width: sequence.width,
            height: sequence.height,
            prompt: None,
            categories,
            guides: self.guides.clone(),
        })
    }

    fn read(&self, key: &Path) -> Result<RawScene, SceneError> {
        let (sequence, frame) = self.scene(key)?;
        sequence.check(frame)?;
        let depth = sequence.depth(frame)?;
        let labels = sequence.labels(frame)?;
        let mut category_of = BTreeMap::new();
        let mut attributes = BTreeMap::new();
        for instance in &sequence.instances {
            category_of.insert(instance.index, self.categories[&instance.category].id);
            let mut carried = Map::new();
            carried.insert("instance_id".into(), json!(instance.index));
            if let Some(asset) = &instance.asset_id {
                carried.insert("asset_id".into(), json!(asset));
            }
            if let Some((pose, bbox)) = &instance.boxes[frame] {
                carried.insert("pose".into(), pose.to_json());
                carried.insert("bbox_3d".into(), bbox.to_json());
            }
            attributes.insert(instance.index, carried);
        }
        let rgba = file("rgba", frame);
        let path = sequence.folder.join(&rgba);
        let shaded = match path.exists() {
            true => Some(read_image(&path).map_err(|e| bad(&rgba, e))?.pixels),
            false => None,
        };
        let normals = sequence.normals(frame)?;
        let (width, height) = (sequence.width, sequence.height);
        let camera = Camera::from_intrinsics(width, height, sequence.k, Pose::Given(sequence.poses[frame].0));
        Ok(RawScene {
            width,
            height,
            depth,
            labels,
            category_of,
            attributes,
            shaded,
            normals,
            camera: Some(camera),
            ..RawScene::default()
        })
    }

    fn notes(&self) -> Vec<String> {
        self.notes.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_are_numbered_as_kubric_numbers_them() {
        assert_eq!(frame_number("segmentation_00012.png", "segmentation_", ".png"), Some(12));
        assert_eq!(frame_number("depth_123456.tiff", "depth_", ".tiff"), Some(123456));
        assert_eq!(frame_number("depth_0001.tiff", "depth_", ".tiff"), None);
        assert_eq!(frame_number("segmentation_0000a.png", "segmentation_", ".png"), None);
        assert_eq!(file("depth", 3), "depth_00003.tiff");
        assert_eq!(file("rgba", 12), "rgba_00012.png");
    }
}
