//! BlenderProc's own output, read as its `write_hdf5` writes it: one `<frame>.hdf5` per frame,
//! each array a gzip dataset (`colors` H×W×3 uint8, `depth` planar or `distance` along the ray,
//! H×W float, `instance_segmaps` H×W integers) and `instance_attribute_maps` a JSON byte string of
//! `{"idx", "category_id", "name", …}` per instance, `idx` being its value in the segmentation.
//! Category 0 is background (BlenderProc's default for the world). Where the frame has `normals`
//! (`enable_normals_output`: H×W×3 floats, already in the camera's frame, Blender's camera axes —
//! x right, y up, z toward the viewer — each component c stored as (c + 1) / 2, so 0.5 is no
//! normal, the background's), they become the frame's normals. Read in Rust (`hdf5-reader`), with
//! no HDF5 library on the system.

use crate::format::{SceneFormat, SceneIndex};
use crate::labels::{CategoryGuide, RawScene};
use crate::SceneError;
use hdf5_reader::{ByteOrder, Datatype, Hdf5File};
use serde::Deserialize;
use serde_json::{json, Map};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use vkdiff_render::coco::Category;

#[derive(Deserialize)]
struct InstanceAttributes {
    idx: u32,
    category_id: u32,
    #[serde(default)]
    name: Option<String>,
}

/// BlenderProc's frame files, in frame-number order.
#[derive(Debug)]
pub struct BlenderProcFrames {
    /// categories.json beside the files, naming the category ids; else `category_<id>`.
    names: Option<Vec<Category>>,
    /// What that categories.json says of how categories are generated.
    guides: BTreeMap<u32, CategoryGuide>,
}

impl BlenderProcFrames {
    pub fn new(dir: &Path) -> Result<BlenderProcFrames, SceneError> {
        let path = dir.join("categories.json");
        let listed = path.is_file().then(|| crate::labels::read_categories(&path)).transpose()?;
        let (names, guides) = match listed {
            Some((names, _, guides)) => (Some(names), guides),
            None => (None, BTreeMap::new()),
        };
        Ok(BlenderProcFrames { names, guides })
    }

    /// The `.hdf5` (or `.h5`) files among `paths`, numbered as BlenderProc numbers them (0.hdf5,
    /// 1.hdf5, …, 10.hdf5); None where there is none.
    pub fn find(paths: &[PathBuf]) -> Option<Vec<PathBuf>> {
        let mut found: Vec<PathBuf> =
            paths.iter().filter(|p| p.extension().is_some_and(|e| e == "hdf5" || e == "h5")).cloned().collect();
        found.sort_by_key(|p| (stem_number(p), p.clone()));
        (!found.is_empty()).then_some(found)
    }

    /// A category id's name: from categories.json beside the files, else `category_<id>`.
    fn category(&self, id: u32) -> Category {
        let listed = self.names.as_ref().and_then(|names| names.iter().find(|c| c.id == id));
        listed.cloned().unwrap_or_else(|| {
            let name = format!("category_{id}");
            Category::new(id, &name, &name)
        })
    }
}

/// A file's stem as a number (`12.hdf5` → 12), else past every number.
fn stem_number(path: &Path) -> u64 {
    path.file_stem().and_then(|s| s.to_str()).and_then(|s| s.parse().ok()).unwrap_or(u64::MAX)
}

impl SceneFormat for BlenderProcFrames {
    fn name(&self) -> &'static str {
        "blenderproc hdf5"
    }

    fn index(&self, path: &Path) -> Result<SceneIndex, SceneError> {
        let frame = Frame::open(path)?;
        let mut used: Vec<u32> = frame.instances.iter().map(|i| i.category_id).filter(|&c| c != 0).collect();
        used.sort_unstable();
        used.dedup();
        let categories = used.into_iter().map(|id| self.category(id)).collect();
        Ok(SceneIndex {
            width: frame.width as u32,
            height: frame.height as u32,
            prompt: None,
            categories,
            guides: self.guides.clone(),
        })
    }

    fn read(&self, path: &Path) -> Result<RawScene, SceneError> {
        Frame::open(path)?.read()
    }
}

fn fail(why: String) -> SceneError {
    SceneError::new(why)
}

/// One frame file, its datasets found and their shapes and instance list checked; no pixel read.
struct Frame {
    width: usize,
    height: usize,
    segmap: hdf5_reader::Dataset,
    depth: hdf5_reader::Dataset,
    colors: Option<hdf5_reader::Dataset>,
    normals: Option<hdf5_reader::Dataset>,
    instances: Vec<InstanceAttributes>,
}

impl Frame {
    fn open(path: &Path) -> Result<Frame, SceneError> {
        let file = Hdf5File::open(path).map_err(|e| fail(format!("not an HDF5 file BlenderProc wrote: {e}")))?;
        // A copy cut short (an interrupted transfer) opens, then lacks whatever lay past its end.
        let (size, end) = (std::fs::metadata(path).map_or(0, |m| m.len()), file.superblock().eof_address);
        if size < end {
            return Err(fail(format!("cut short: {size} bytes, where its HDF5 superblock says {end}")));
        }
        let dataset = |name: &str| file.dataset(&format!("/{name}")).ok();
        let segmap = dataset("instance_segmaps").ok_or_else(|| {
            fail("no `instance_segmaps` (BlenderProc writes it with bproc.renderer.enable_segmentation_output(map_by=[\"instance\", ...]))".into())
        })?;
        let shape = |d: &hdf5_reader::Dataset| d.shape().iter().map(|&s| s as usize).collect::<Vec<_>>();
        let dims = shape(&segmap);
        let [height, width] = dims[..] else {
            return Err(fail(format!(
                "`instance_segmaps` has shape {dims:?}; one H×W map per file (stereo pairs: write them as key_0/key_1 files)"
            )));
        };
        integer_width(&segmap).map_err(|why| fail(format!("`instance_segmaps`: {why}")))?;
        let depth = dataset("depth")
            .or_else(|| dataset("distance"))
            .ok_or_else(|| fail("no `depth` or `distance` (bproc.renderer.enable_depth_output)".into()))?;
        if shape(&depth) != [height, width] {
            return Err(fail(format!(
                "`{}` has shape {:?}, the segmentation {height}×{width}",
                depth.name(),
                shape(&depth)
            )));
        }
        float_width(&depth).map_err(|why| fail(format!("`{}`: {why}", depth.name())))?;
        let attributes = dataset("instance_attribute_maps")
            .ok_or_else(|| fail("no `instance_attribute_maps` (map_by must include \"category_id\")".into()))?;
        let text = attributes.read_string().map_err(|e| fail(format!("`instance_attribute_maps`: {e}")))?;
        let instances: Vec<InstanceAttributes> = serde_json::from_str(&text)
            .map_err(|e| fail(format!("`instance_attribute_maps` is not a list of {{idx, category_id}}: {e}")))?;
        let colors = dataset("colors");
        if let Some(colors) = &colors {
            rgb_channels(colors, width, height).map_err(|why| fail(format!("`colors`: {why}")))?;
        }
        let normals = dataset("normals");
        if let Some(normals) = &normals {
            if shape(normals) != [height, width, 3] {
                return Err(fail(format!(
                    "`normals` has shape {:?}; expected {height}×{width}×3, one normal per pixel of the segmentation",
                    shape(normals)
                )));
            }
            float_width(normals).map_err(|why| fail(format!("`normals`: {why}")))?;
        }
        let mut seen = std::collections::BTreeSet::new();
        if let Some(twice) = instances.iter().find(|i| !seen.insert(i.idx)) {
            return Err(fail(format!("`instance_attribute_maps` lists idx {} twice", twice.idx)));
        }
        Ok(Frame { width, height, segmap, depth, colors, normals, instances })
    }

    /// The frame's pixels.
    fn read(self) -> Result<RawScene, SceneError> {
        let labels = integers(&self.segmap).map_err(|why| fail(format!("`instance_segmaps`: {why}")))?;
        let depth = floats(&self.depth).map_err(|why| fail(format!("`{}`: {why}", self.depth.name())))?;
        let shaded = match &self.colors {
            Some(colors) => Some(rgb(colors, self.width, self.height).map_err(|why| fail(format!("`colors`: {why}")))?),
            None => None,
        };
        let normals = match &self.normals {
            Some(normals) => Some(camera_normals(normals).map_err(|why| fail(format!("`normals`: {why}")))?),
            None => None,
        };
        let category_of = self.instances.iter().map(|i| (i.idx, i.category_id)).collect();
        let attributes = self
            .instances
            .iter()
            .filter_map(|i| i.name.as_ref().map(|name| (i.idx, Map::from_iter([("name".to_string(), json!(name))]))))
            .collect::<BTreeMap<_, _>>();
        let (width, height) = (self.width as u32, self.height as u32);
        Ok(RawScene { width, height, depth, labels, category_of, attributes, shaded, normals, ..RawScene::default() })
    }
}

/// BlenderProc's normals as the frame holds them: each stored component v is (c + 1) / 2 of c in
/// Blender's camera axes (x right, y up, z toward the viewer), so c = 2v − 1 (in f32), and
/// OpenCV's axes (x right, y down, z forward) are (c_x, −c_y, −c_z).
fn camera_normals(d: &hdf5_reader::Dataset) -> Result<Vec<[f32; 3]>, String> {
    let c = |v: f32| 2.0 * v - 1.0;
    Ok(floats(d)?.chunks_exact(3).map(|v| [c(v[0]), -c(v[1]), -c(v[2])]).collect())
}

/// An integer dataset's width in bytes (1 to 8), signedness and byte order.
fn integer_width(d: &hdf5_reader::Dataset) -> Result<(usize, bool, ByteOrder), String> {
    match d.dtype().clone() {
        Datatype::FixedPoint { size: size @ 1..=8, signed, byte_order } => Ok((size as usize, signed, byte_order)),
        other => Err(format!("{other:?}, expected integers")),
    }
}

/// An integer dataset's values (any width, signed or not, either byte order).
fn integers(d: &hdf5_reader::Dataset) -> Result<Vec<u32>, String> {
    let (size, signed, byte_order) = integer_width(d)?;
    let bytes = d.read_raw_bytes().map_err(|e| e.to_string())?;
    bytes
        .chunks_exact(size)
        .map(|b| {
            let mut word = [0u8; 8];
            match byte_order {
                ByteOrder::LittleEndian => word[..size].copy_from_slice(b),
                _ => word[..size].iter_mut().zip(b.iter().rev()).for_each(|(w, &v)| *w = v),
            }
            let unsigned = u64::from_le_bytes(word);
            let value = if signed && size < 8 && unsigned >> (8 * size - 1) & 1 == 1 {
                (unsigned as i64) - (1i64 << (8 * size))
            } else {
                unsigned as i64
            };
            u32::try_from(value).map_err(|_| format!("value {value} is not an instance id"))
        })
        .collect()
}

/// A floating-point dataset's width in bytes (2, 4 or 8) and whether it is little-endian.
fn float_width(d: &hdf5_reader::Dataset) -> Result<(usize, bool), String> {
    match d.dtype().clone() {
        Datatype::FloatingPoint { size: size @ (2 | 4 | 8), byte_order } => {
            Ok((size as usize, matches!(byte_order, ByteOrder::LittleEndian)))
        }
        Datatype::FloatingPoint { size, .. } => Err(format!("{size}-byte floats")),
        other => Err(format!("{other:?}, expected floating point")),
    }
}

/// A floating-point dataset's values as f32 (16, 32 or 64 bits).
fn floats(d: &hdf5_reader::Dataset) -> Result<Vec<f32>, String> {
    let (size, little) = float_width(d)?;
    let bytes = d.read_raw_bytes().map_err(|e| e.to_string())?;
    let word = |b: &[u8]| -> Vec<u8> {
        if little {
            b.to_vec()
        } else {
            b.iter().rev().copied().collect()
        }
    };
    Ok(match size {
        2 => bytes.chunks_exact(2).map(|b| half::f16::from_le_bytes(word(b).try_into().unwrap()).to_f32()).collect(),
        4 => bytes.chunks_exact(4).map(|b| f32::from_le_bytes(word(b).try_into().unwrap())).collect(),
        _ => bytes.chunks_exact(8).map(|b| f64::from_le_bytes(word(b).try_into().unwrap()) as f32).collect(),
    })
}

/// The channels of `colors`: H×W×3 or H×W×4 unsigned bytes.
fn rgb_channels(d: &hdf5_reader::Dataset, width: usize, height: usize) -> Result<usize, String> {
    let dims: Vec<u64> = d.shape().to_vec();
    let channels = match dims[..] {
        [h, w, c @ (3 | 4)] if (h as usize, w as usize) == (height, width) => c as usize,
        _ => return Err(format!("shape {dims:?}; expected {height}×{width}×3 (or 4)")),
    };
    if !matches!(d.dtype(), Datatype::FixedPoint { size: 1, signed: false, .. }) {
        return Err(format!("{:?}; expected 8-bit colours", d.dtype()));
    }
    Ok(channels)
}

/// `colors` as 8-bit RGB (alpha dropped).
fn rgb(d: &hdf5_reader::Dataset, width: usize, height: usize) -> Result<Vec<u8>, String> {
    let channels = rgb_channels(d, width, height)?;
    let bytes = d.read_raw_bytes().map_err(|e| e.to_string())?;
    Ok(bytes.chunks_exact(channels).flat_map(|px| [px[0], px[1], px[2]]).collect())
}
