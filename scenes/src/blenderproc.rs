//! BlenderProc's own output, read as its `write_hdf5` writes it: one `<frame>.hdf5` per frame,
//! each array a gzip dataset (`colors` H×W×3 uint8, `depth` planar or `distance` along the ray,
//! H×W float, `instance_segmaps` H×W integers) and `instance_attribute_maps` a JSON byte string of
//! `{"idx", "category_id", "name", …}` per instance, `idx` being its value in the segmentation.
//! Category 0 is background (BlenderProc's default for the world). Read in Rust (`hdf5-reader`),
//! with no HDF5 library on the system.

use crate::labels::RawScene;
use crate::SceneError;
use hdf5_reader::{ByteOrder, Datatype, Hdf5File};
use serde::Deserialize;
use serde_json::{json, Map};
use std::collections::BTreeMap;
use std::path::Path;

#[derive(Deserialize)]
struct InstanceAttributes {
    idx: u32,
    category_id: u32,
    #[serde(default)]
    name: Option<String>,
}

/// Reads one BlenderProc frame file; the category ids it uses come back with it.
pub fn read_hdf5(path: &Path) -> Result<(RawScene, Vec<u32>), SceneError> {
    let fail = |why: String| SceneError::new(why);
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
    let labels = integers(&segmap).map_err(|why| fail(format!("`instance_segmaps`: {why}")))?;
    let depth_set = dataset("depth")
        .or_else(|| dataset("distance"))
        .ok_or_else(|| fail("no `depth` or `distance` (bproc.renderer.enable_depth_output)".into()))?;
    if shape(&depth_set) != [height, width] {
        return Err(fail(format!(
            "`{}` has shape {:?}, the segmentation {height}×{width}",
            depth_set.name(),
            shape(&depth_set)
        )));
    }
    let depth = floats(&depth_set).map_err(|why| fail(format!("`{}`: {why}", depth_set.name())))?;
    let attributes = dataset("instance_attribute_maps")
        .ok_or_else(|| fail("no `instance_attribute_maps` (map_by must include \"category_id\")".into()))?;
    let text = attributes.read_string().map_err(|e| fail(format!("`instance_attribute_maps`: {e}")))?;
    let list: Vec<InstanceAttributes> = serde_json::from_str(&text)
        .map_err(|e| fail(format!("`instance_attribute_maps` is not a list of {{idx, category_id}}: {e}")))?;
    let mut category_of = BTreeMap::new();
    let mut named = BTreeMap::new();
    for instance in &list {
        if category_of.insert(instance.idx, instance.category_id).is_some() {
            return Err(fail(format!("`instance_attribute_maps` lists idx {} twice", instance.idx)));
        }
        if let Some(name) = &instance.name {
            named.insert(instance.idx, Map::from_iter([("name".to_string(), json!(name))]));
        }
    }
    let shaded = match dataset("colors") {
        Some(colors) => Some(rgb(&colors, width, height).map_err(|why| fail(format!("`colors`: {why}")))?),
        None => None,
    };
    let mut used: Vec<u32> = list.iter().map(|i| i.category_id).filter(|&c| c != 0).collect();
    used.sort_unstable();
    used.dedup();
    let raw =
        RawScene { width: width as u32, height: height as u32, depth, labels, category_of, attributes: named, shaded };
    Ok((raw, used))
}

/// An integer dataset's values (any width, signed or not, either byte order).
fn integers(d: &hdf5_reader::Dataset) -> Result<Vec<u32>, String> {
    let Datatype::FixedPoint { size, signed, byte_order } = d.dtype().clone() else {
        return Err(format!("{:?}, expected integers", d.dtype()));
    };
    let bytes = d.read_raw_bytes().map_err(|e| e.to_string())?;
    let size = size as usize;
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

/// A floating-point dataset's values as f32 (16, 32 or 64 bits).
fn floats(d: &hdf5_reader::Dataset) -> Result<Vec<f32>, String> {
    let Datatype::FloatingPoint { size, byte_order } = d.dtype().clone() else {
        return Err(format!("{:?}, expected floating point", d.dtype()));
    };
    let bytes = d.read_raw_bytes().map_err(|e| e.to_string())?;
    let little = matches!(byte_order, ByteOrder::LittleEndian);
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
        8 => bytes.chunks_exact(8).map(|b| f64::from_le_bytes(word(b).try_into().unwrap()) as f32).collect(),
        other => return Err(format!("{other}-byte floats")),
    })
}

/// `colors` as 8-bit RGB: H×W×3 or H×W×4 (alpha dropped) unsigned bytes.
fn rgb(d: &hdf5_reader::Dataset, width: usize, height: usize) -> Result<Vec<u8>, String> {
    let dims: Vec<u64> = d.shape().to_vec();
    let channels = match dims[..] {
        [h, w, c @ (3 | 4)] if (h as usize, w as usize) == (height, width) => c as usize,
        _ => return Err(format!("shape {dims:?}; expected {height}×{width}×3 (or 4)")),
    };
    if !matches!(d.dtype(), Datatype::FixedPoint { size: 1, signed: false, .. }) {
        return Err(format!("{:?}; expected 8-bit colours", d.dtype()));
    }
    let bytes = d.read_raw_bytes().map_err(|e| e.to_string())?;
    Ok(bytes.chunks_exact(channels).flat_map(|px| [px[0], px[1], px[2]]).collect())
}
