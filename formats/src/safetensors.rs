//! Memory-mapped safetensors files: an 8-byte little-endian header length, a JSON header naming
//! each tensor's dtype, shape and byte range, then the data.

use crate::error::{Error, Result};
use crate::float8::{e4m3fn_to_f32, e5m2_to_f32};
use half::{bf16, f16};
use memmap2::Mmap;
use serde_json::Value;
use std::collections::BTreeMap;
use std::fs::File;
use std::path::{Path, PathBuf};

/// Element types vkdiff reads; anything else is reported when asked for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SourceDtype {
    F32,
    F16,
    BF16,
    /// torch's `float8_e4m3fn`.
    F8E4M3,
    /// torch's `float8_e5m2`.
    F8E5M2,
    Other(&'static str),
}

impl SourceDtype {
    /// The dtype named in a header, and its bytes per element where fixed.
    fn parse(name: &str) -> (SourceDtype, Option<usize>) {
        match name {
            "F32" => (SourceDtype::F32, Some(4)),
            "F16" => (SourceDtype::F16, Some(2)),
            "BF16" => (SourceDtype::BF16, Some(2)),
            "F8_E4M3" => (SourceDtype::F8E4M3, Some(1)),
            "F8_E5M2" => (SourceDtype::F8E5M2, Some(1)),
            "F64" => (SourceDtype::Other("F64"), Some(8)),
            "I64" => (SourceDtype::Other("I64"), Some(8)),
            "I32" => (SourceDtype::Other("I32"), Some(4)),
            "I8" | "U8" | "BOOL" => (SourceDtype::Other("8-bit"), Some(1)),
            _ => (SourceDtype::Other("an unknown dtype"), None),
        }
    }
}

/// Where one tensor lives in its file.
#[derive(Clone, Debug)]
pub struct Entry {
    pub dtype: SourceDtype,
    pub shape: Vec<usize>,
    element_size: Option<usize>,
    start: usize,
    end: usize,
}

/// A file's bytes: mapped from disk, or held (a checkpoint of another format converted in memory).
enum Bytes {
    Mapped(Mmap),
    Owned(Vec<u8>),
}

impl std::ops::Deref for Bytes {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        match self {
            Bytes::Mapped(m) => m,
            Bytes::Owned(v) => v,
        }
    }
}

/// One open safetensors file.
pub struct SafeTensors {
    pub path: PathBuf,
    map: Bytes,
    data_start: usize,
    pub entries: BTreeMap<String, Entry>,
    /// The header's `__metadata__` strings (other values are left out).
    pub metadata: BTreeMap<String, String>,
}

impl SafeTensors {
    /// Maps `path` and checks its header as the reference loader does: every tensor's range must
    /// lie inside the file and match its dtype and shape, and the ranges must tile the data
    /// without overlap, so a truncated download or a forged header is caught here, naming the
    /// tensor.
    pub fn open(path: &Path) -> Result<SafeTensors> {
        let file = File::open(path).map_err(|e| Error::Io { path: path.to_path_buf(), source: e })?;
        // SAFETY: the file is only read; a concurrent writer would be the user's error, as with any mmap reader.
        let map = unsafe { Mmap::map(&file) }.map_err(|e| Error::Io { path: path.to_path_buf(), source: e })?;
        SafeTensors::parse(path, Bytes::Mapped(map))
    }

    /// A safetensors file's `bytes` held in memory, checked as [`SafeTensors::open`] checks a
    /// file; `path` names it in errors.
    pub fn from_bytes(path: &Path, bytes: Vec<u8>) -> Result<SafeTensors> {
        SafeTensors::parse(path, Bytes::Owned(bytes))
    }

    fn parse(path: &Path, map: Bytes) -> Result<SafeTensors> {
        let bad = |why: String| Error::Format { path: path.to_path_buf(), why };
        if map.len() < 8 {
            return Err(bad(format!("{} bytes is too short for a safetensors file", map.len())));
        }
        let header_len = u64::from_le_bytes(map[..8].try_into().unwrap()) as usize;
        if header_len > map.len() - 8 {
            return Err(bad(format!(
                "header of {header_len} bytes runs past the end of the {}-byte file (truncated, or not safetensors)",
                map.len()
            )));
        }
        let header: Value =
            serde_json::from_slice(&map[8..8 + header_len]).map_err(|e| bad(format!("header is not JSON: {e}")))?;
        let Value::Object(fields) = header else { return Err(bad("header is not a JSON object".into())) };
        let data_start = 8 + header_len;
        let data_len = map.len() - data_start;
        let mut entries = BTreeMap::new();
        let mut metadata = BTreeMap::new();
        for (name, v) in fields {
            if name == "__metadata__" {
                if let Value::Object(m) = v {
                    metadata.extend(m.into_iter().filter_map(|(k, v)| Some((k, v.as_str()?.to_string()))));
                }
                continue;
            }
            let entry = parse_entry(&v).ok_or_else(|| bad(format!("tensor `{name}` has a malformed header entry")))?;
            if entry.end > data_len {
                return Err(bad(format!(
                    "tensor `{name}` ends at byte {} but the file holds {data_len} bytes of data (truncated?)",
                    entry.end
                )));
            }
            let bytes = entry
                .shape
                .iter()
                .try_fold(1usize, |n, &d| n.checked_mul(d))
                .and_then(|n| entry.element_size.map_or(Some(n), |s| n.checked_mul(s)));
            match (bytes, entry.element_size) {
                (None, _) => {
                    return Err(bad(format!("tensor `{name}`: shape {:?} is too large to exist", entry.shape)))
                }
                (Some(b), Some(_)) if b != entry.end - entry.start => {
                    return Err(bad(format!(
                        "tensor `{name}`: {} bytes for shape {:?}",
                        entry.end - entry.start,
                        entry.shape
                    )))
                }
                _ => {}
            }
            entries.insert(name, entry);
        }
        let mut ranges: Vec<(usize, usize, &String)> = entries.iter().map(|(n, e)| (e.start, e.end, n)).collect();
        ranges.sort();
        let mut covered = 0;
        for (start, end, name) in ranges {
            if start != covered {
                let what = if start < covered {
                    "overlaps the tensor before it"
                } else {
                    "leaves a gap after the tensor before it"
                };
                return Err(bad(format!("tensor `{name}` (bytes {start}..{end}) {what}")));
            }
            covered = end;
        }
        if covered != data_len {
            return Err(bad(format!("the tensors cover {covered} of the file's {data_len} bytes of data")));
        }
        Ok(SafeTensors { path: path.to_path_buf(), map, data_start, entries, metadata })
    }

    /// The raw little-endian bytes of a tensor.
    pub fn bytes(&self, entry: &Entry) -> &[u8] {
        &self.map[self.data_start + entry.start..self.data_start + entry.end]
    }

    /// A floating-point tensor's shape and values as f32.
    pub fn values(&self, name: &str) -> Result<(Vec<usize>, Vec<f32>)> {
        let entry = self
            .entries
            .get(name)
            .ok_or_else(|| Error::Tensor(format!("tensor `{name}` is missing from {}", self.path.display())))?;
        let values = decode(entry.dtype, self.bytes(entry)).ok_or_else(|| {
            Error::Tensor(format!(
                "tensor `{name}` in {} is not F32, F16, BF16 or F8 (E4M3, E5M2)",
                self.path.display()
            ))
        })?;
        Ok((entry.shape.clone(), values))
    }
}

/// Little-endian floats as f32; `None` for the types vkdiff does not read.
pub fn decode(dtype: SourceDtype, bytes: &[u8]) -> Option<Vec<f32>> {
    Some(match dtype {
        SourceDtype::F32 => bytes.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect(),
        SourceDtype::F16 => bytes.chunks_exact(2).map(|c| f16::from_le_bytes([c[0], c[1]]).to_f32()).collect(),
        SourceDtype::BF16 => bytes.chunks_exact(2).map(|c| bf16::from_le_bytes([c[0], c[1]]).to_f32()).collect(),
        SourceDtype::F8E4M3 => bytes.iter().map(|&b| e4m3fn_to_f32(b)).collect(),
        SourceDtype::F8E5M2 => bytes.iter().map(|&b| e5m2_to_f32(b)).collect(),
        SourceDtype::Other(_) => return None,
    })
}

fn parse_entry(v: &Value) -> Option<Entry> {
    let (dtype, element_size) = SourceDtype::parse(v.get("dtype")?.as_str()?);
    let shape =
        v.get("shape")?.as_array()?.iter().map(|d| d.as_u64().map(|d| d as usize)).collect::<Option<Vec<_>>>()?;
    let offsets = v.get("data_offsets")?.as_array()?;
    let (start, end) = (offsets.first()?.as_u64()? as usize, offsets.get(1)?.as_u64()? as usize);
    (start <= end).then_some(Entry { dtype, shape, element_size, start, end })
}

/// Writes f32 tensors as a safetensors file with string metadata, atomically, so an interrupted
/// run leaves no truncated file.
pub fn write_f32(path: &Path, tensors: &[(&str, &[usize], &[f32])], metadata: &BTreeMap<String, String>) -> Result<()> {
    crate::atomic::write_atomic(path, &f32_file_bytes(tensors, metadata))
}

/// The bytes of a safetensors file of f32 tensors with string metadata.
pub fn f32_file_bytes(tensors: &[(&str, &[usize], &[f32])], metadata: &BTreeMap<String, String>) -> Vec<u8> {
    let shapes: Vec<(&str, &str, &[usize])> = tensors.iter().map(|(n, s, _)| (*n, "F32", *s)).collect();
    let mut bytes = header_bytes(&shapes, metadata);
    for (_, _, data) in tensors {
        bytes.extend(data.iter().flat_map(|v| v.to_le_bytes()));
    }
    bytes
}

/// Writes tensors of `shapes` in f16, the values of tensor i made by `values(i)` only as it is
/// written (a whole SDXL is 7 GB), atomically.
pub fn write_f16_streamed(
    path: &Path,
    shapes: &[(&str, &[usize])],
    metadata: &BTreeMap<String, String>,
    values: &mut dyn FnMut(usize) -> Vec<f32>,
) -> Result<()> {
    crate::atomic::write_atomic_with(path, &mut |out| {
        let typed: Vec<(&str, &str, &[usize])> = shapes.iter().map(|(n, s)| (*n, "F16", *s)).collect();
        out.write_all(&header_bytes(&typed, metadata))?;
        for (i, (name, shape)) in shapes.iter().enumerate() {
            let data = values(i);
            assert_eq!(data.len(), shape.iter().product::<usize>(), "values of {name}");
            let halves: Vec<u8> = data.iter().flat_map(|&v| f16::from_f32(v).to_le_bytes()).collect();
            out.write_all(&halves)?;
        }
        Ok(())
    })
}

/// The bytes of a safetensors file of tensors (name, dtype as the header names it, shape, their
/// little-endian bytes), in order.
pub fn file_bytes(tensors: &[(&str, &str, &[usize], &[u8])]) -> Vec<u8> {
    let shapes: Vec<(&str, &str, &[usize])> = tensors.iter().map(|(n, d, s, _)| (*n, *d, *s)).collect();
    let mut bytes = header_bytes(&shapes, &BTreeMap::new());
    for (_, _, _, data) in tensors {
        bytes.extend_from_slice(data);
    }
    bytes
}

/// The length-prefixed JSON header of tensors (name, dtype, shape), in order, with string
/// metadata, padded with spaces so the data starts 8-byte aligned as the format's writers align it.
fn header_bytes(tensors: &[(&str, &str, &[usize])], metadata: &BTreeMap<String, String>) -> Vec<u8> {
    let mut header = serde_json::Map::new();
    if !metadata.is_empty() {
        header.insert("__metadata__".into(), serde_json::to_value(metadata).expect("strings serialise"));
    }
    let mut offset = 0;
    for (name, dtype, shape) in tensors {
        let size = SourceDtype::parse(dtype).1.expect("a dtype of fixed size");
        let end = offset + size * shape.iter().product::<usize>();
        header.insert(
            (*name).into(),
            serde_json::json!({ "dtype": dtype, "shape": shape, "data_offsets": [offset, end] }),
        );
        offset = end;
    }
    let mut json = serde_json::to_vec(&Value::Object(header)).expect("header serialises");
    json.resize(json.len().div_ceil(8) * 8, b' ');
    let mut bytes = (json.len() as u64).to_le_bytes().to_vec();
    bytes.extend(json);
    bytes
}
