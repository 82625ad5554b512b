//! PyTorch checkpoints as `torch.save` writes them: a zip archive (torch >= 1.6) holding the pickled
//! object as `<archive>/data.pkl` and each storage as `<archive>/data/<key>`, or the legacy format
//! (consecutive pickles, then the storages back to back). vkdiff reads a flat dict of tensors (a
//! state dict), e.g. torch-fidelity's InceptionV3 weights, without running any pickled code.

use crate::error::{Error, Result};
use crate::safetensors::SafeTensors;
use crate::stored_zip::{le, zip_entries};
use crate::torch_pickle::{self, Id, Obj, Pickle};
use half::{bf16, f16};
use std::collections::{BTreeMap, HashMap};
use std::ops::Range;
use std::path::{Path, PathBuf};

/// Parse errors before the file's path is attached.
type Parsed<T> = std::result::Result<T, String>;

/// The number torch's legacy format opens with.
const LEGACY_MAGIC: i128 = 0x1950a86a20f9469cfc6c;

/// Element types of torch storages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Dtype {
    F32,
    F16,
    BF16,
    F64,
    /// Not a float type: its torch name and bytes per element.
    Other(&'static str, usize),
}

impl Dtype {
    /// From a pickled storage type (`torch.FloatStorage`) or dtype (`torch.float32`).
    fn from_global(module: &str, name: &str) -> Option<Dtype> {
        if module != "torch" && !module.starts_with("torch.") {
            return None;
        }
        Some(match name {
            "FloatStorage" | "float32" | "float" => Dtype::F32,
            "HalfStorage" | "float16" | "half" => Dtype::F16,
            "BFloat16Storage" | "bfloat16" => Dtype::BF16,
            "DoubleStorage" | "float64" | "double" => Dtype::F64,
            "LongStorage" | "int64" | "long" => Dtype::Other("int64", 8),
            "IntStorage" | "int32" | "int" => Dtype::Other("int32", 4),
            "ShortStorage" | "int16" | "short" => Dtype::Other("int16", 2),
            "CharStorage" | "int8" => Dtype::Other("int8", 1),
            "ByteStorage" | "uint8" | "UntypedStorage" => Dtype::Other("uint8", 1),
            "BoolStorage" | "bool" => Dtype::Other("bool", 1),
            "ComplexFloatStorage" | "complex64" => Dtype::Other("complex64", 8),
            "ComplexDoubleStorage" | "complex128" => Dtype::Other("complex128", 16),
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Dtype::F32 => 4,
            Dtype::F16 | Dtype::BF16 => 2,
            Dtype::F64 => 8,
            Dtype::Other(_, size) => size,
        }
    }
}

/// A tensor as torch saved it: a strided view of a storage.
#[derive(Debug)]
struct Tensor {
    dtype: Dtype,
    shape: Vec<usize>,
    stride: Vec<usize>,
    /// In elements, from the start of the storage.
    offset: usize,
    /// The storage's key, and its bytes in the file once found.
    key: String,
    bytes: Range<usize>,
}

/// One PyTorch checkpoint, read whole into memory.
pub struct TorchPth {
    pub path: PathBuf,
    data: Vec<u8>,
    tensors: BTreeMap<String, Tensor>,
}

impl TorchPth {
    /// Reads the whole file (it is ~100 MB at most for our use) and parses it.
    pub fn open(path: &Path) -> Result<TorchPth> {
        let data = std::fs::read(path).map_err(|source| Error::Io { path: path.to_path_buf(), source })?;
        TorchPth::parse(path.to_path_buf(), data)
    }

    fn parse(path: PathBuf, data: Vec<u8>) -> Result<TorchPth> {
        let tensors = if data.starts_with(b"PK\x03\x04") { read_zip(&data) } else { read_legacy(&data) };
        match tensors.and_then(|tensors| check(tensors, data.len())) {
            Ok(tensors) => Ok(TorchPth { path, data, tensors }),
            Err(why) => Err(Error::Format { path, why }),
        }
    }

    /// Tensor names, sorted.
    pub fn names(&self) -> Vec<String> {
        self.tensors.keys().cloned().collect()
    }

    /// Shape of a tensor if present.
    pub fn shape(&self, name: &str) -> Option<Vec<usize>> {
        self.tensors.get(name).map(|t| t.shape.clone())
    }

    /// The checkpoint as an in-memory safetensors file: every floating-point tensor contiguous, in
    /// its own dtype (F64 narrowed to F32); integer and boolean tensors (buffers, step counters)
    /// are left out.
    pub fn to_safetensors(&self) -> Result<SafeTensors> {
        let mut stored: Vec<(&str, &str, Vec<usize>, Vec<u8>)> = Vec::new();
        for (name, t) in &self.tensors {
            let (shape, values) = match t.dtype {
                Dtype::Other(..) => continue,
                _ => self.values(name)?,
            };
            // Widened exactly by `values`, so narrowed back exactly.
            let (dtype, bytes): (&str, Vec<u8>) = match t.dtype {
                Dtype::F16 => ("F16", values.iter().flat_map(|&v| f16::from_f32(v).to_le_bytes()).collect()),
                Dtype::BF16 => ("BF16", values.iter().flat_map(|&v| bf16::from_f32(v).to_le_bytes()).collect()),
                _ => ("F32", values.iter().flat_map(|v| v.to_le_bytes()).collect()),
            };
            stored.push((name, dtype, shape, bytes));
        }
        let tensors: Vec<(&str, &str, &[usize], &[u8])> =
            stored.iter().map(|(n, d, s, b)| (*n, *d, s.as_slice(), b.as_slice())).collect();
        SafeTensors::from_bytes(&self.path, crate::safetensors::file_bytes(&tensors))
    }

    /// A tensor's values as f32 in row-major (C-contiguous) order of its shape, honouring the
    /// storage offset and strides torch saved (non-contiguous/transposed views, shared storages).
    pub fn values(&self, name: &str) -> Result<(Vec<usize>, Vec<f32>)> {
        let t = self
            .tensors
            .get(name)
            .ok_or_else(|| Error::Tensor(format!("tensor `{name}` is missing from {}", self.path.display())))?;
        let read: fn(&[u8]) -> f32 = match t.dtype {
            Dtype::F32 => |b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            Dtype::F16 => |b| f16::from_le_bytes([b[0], b[1]]).to_f32(),
            Dtype::BF16 => |b| bf16::from_le_bytes([b[0], b[1]]).to_f32(),
            Dtype::F64 => |b| f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]) as f32,
            Dtype::Other(dtype, _) => {
                return Err(Error::Tensor(format!(
                    "tensor `{name}` in {} is {dtype}, not a floating-point tensor",
                    self.path.display()
                )))
            }
        };
        let (storage, size) = (&self.data[t.bytes.clone()], t.dtype.size());
        let numel = t.shape.iter().product();
        let mut values = Vec::with_capacity(numel);
        let mut index = vec![0; t.shape.len()];
        let mut at = t.offset;
        for _ in 0..numel {
            values.push(read(&storage[at * size..(at + 1) * size]));
            // Step to the next element in row-major order. `check` proved every element lies in the storage; wrapping
            // arithmetic only matters for the step past a dimension's end, which is undone at once.
            for d in (0..t.shape.len()).rev() {
                index[d] += 1;
                at = at.wrapping_add(t.stride[d]);
                if index[d] < t.shape[d] {
                    break;
                }
                at = at.wrapping_sub(t.stride[d].wrapping_mul(t.shape[d]));
                index[d] = 0;
            }
        }
        Ok((t.shape.clone(), values))
    }
}

fn read_zip(data: &[u8]) -> Parsed<BTreeMap<String, Tensor>> {
    let entries = zip_entries(data)?;
    // The archive folder is the file's stem in older torch and `archive` in newer: find it by its pickle.
    let pickles: Vec<&String> =
        entries.keys().filter(|n| n.ends_with("/data.pkl") && n.matches('/').count() == 1).collect();
    let [pickle] = pickles[..] else {
        return Err(format!(
            "the zip holds {} entries named <folder>/data.pkl where torch.save writes one",
            pickles.len()
        ));
    };
    let folder = &pickle[..pickle.len() - "data.pkl".len()];
    if let Some(order) = entries.get(&format!("{folder}byteorder")) {
        if data[order.clone()] != *b"little" {
            return Err(format!(
                "byte order `{}`: vkdiff reads little-endian checkpoints",
                String::from_utf8_lossy(&data[order.clone()])
            ));
        }
    }
    let (object, _) = torch_pickle::load(&data[entries[pickle].clone()]).map_err(|e| format!("{pickle}: {e}"))?;
    let mut tensors = tensors(&object)?;
    for (name, t) in &mut tensors {
        let entry = format!("{folder}data/{}", t.key);
        t.bytes = entries
            .get(&entry)
            .cloned()
            .ok_or_else(|| format!("tensor `{name}`: its storage `{entry}` is missing from the zip"))?;
    }
    Ok(tensors)
}

fn read_legacy(data: &[u8]) -> Parsed<BTreeMap<String, Tensor>> {
    if data.first() != Some(&0x80) {
        return Err("neither a zip archive nor a legacy torch.save pickle: not a PyTorch checkpoint".into());
    }
    let mut pos = 0;
    let mut next = |what: &str| -> Parsed<Pickle> {
        let (pickle, used) = torch_pickle::load(&data[pos..]).map_err(|e| format!("{what}: {e}"))?;
        pos += used;
        Ok(pickle)
    };
    let magic = next("the magic number")?;
    if magic.int(magic.root) != Some(LEGACY_MAGIC) {
        return Err("a pickle, but not one torch.save wrote (no magic number)".into());
    }
    let version = next("the format version")?;
    if version.int(version.root) != Some(1001) {
        return Err("torch.save legacy format version is not 1001".into());
    }
    let info = next("sys_info")?;
    if let Obj::Dict(items) = &info.objs[info.root] {
        if items.iter().any(|&(k, v)| info.str(k) == Some("little_endian") && info.int(v) == Some(0)) {
            return Err("saved on a big-endian machine: vkdiff reads little-endian checkpoints".into());
        }
    }
    let mut tensors = tensors(&next("the checkpoint")?)?;
    let keys = next("the storage keys")?;
    let keys = keys
        .seq(keys.root)
        .ok_or("the storage keys are not a list")?
        .iter()
        .map(|&k| keys.str(k).ok_or("a storage key is not a string"));
    // Each storage: its element count (8 bytes, little-endian), then its data; the element size
    // is the dtype its tensors name.
    let mut dtypes = HashMap::new();
    for t in tensors.values() {
        if *dtypes.entry(t.key.as_str()).or_insert(t.dtype) != t.dtype {
            return Err(format!("storage `{}` is read as two different dtypes", t.key));
        }
    }
    let mut storages = HashMap::new();
    for key in keys {
        let key = key?;
        let dtype = dtypes.get(key).ok_or_else(|| format!("storage `{key}` is listed but no tensor uses it"))?;
        let start = pos + 8;
        let end = le(data, pos, 8)
            .and_then(|count| count.checked_mul(dtype.size())?.checked_add(start))
            .filter(|&end| end <= data.len())
            .ok_or_else(|| format!("storage `{key}` runs past the end of the file (truncated?)"))?;
        storages.insert(key.to_owned(), start..end);
        pos = end;
    }
    for (name, t) in &mut tensors {
        t.bytes = storages
            .get(&t.key)
            .cloned()
            .ok_or_else(|| format!("tensor `{name}`: its storage `{}` is not in the file", t.key))?;
    }
    Ok(tensors)
}

/// The tensors of a pickled dict of tensors, their storages not yet found.
fn tensors(p: &Pickle) -> Parsed<BTreeMap<String, Tensor>> {
    let Obj::Dict(items) = &p.objs[p.root] else {
        return Err(format!(
            "the checkpoint is {}, not a dict of tensors (a whole pickled model? save its state_dict())",
            p.describe(p.root)
        ));
    };
    let mut tensors = BTreeMap::new();
    for &(k, v) in items {
        let name = p
            .str(k)
            .ok_or_else(|| format!("the checkpoint has {} as a key where tensor names are strings", p.describe(k)))?;
        let tensor = rebuild(p, v, 0).map_err(|e| format!("tensor `{name}`: {e}"))?.ok_or_else(|| {
            format!(
                "`{name}` holds {}, not a tensor: vkdiff reads a flat dict of tensors (a state dict)",
                p.describe(v)
            )
        })?;
        tensors.insert(name.to_owned(), tensor);
    }
    Ok(tensors)
}

/// The tensor an object rebuilds, `None` if it is no tensor.
fn rebuild(p: &Pickle, id: Id, depth: u32) -> Parsed<Option<Tensor>> {
    let Obj::Call { func, args } = p.objs[id] else { return Ok(None) };
    rebuild_call(p, func, args, depth)
}

fn rebuild_call(p: &Pickle, func: Id, args: Id, depth: u32) -> Parsed<Option<Tensor>> {
    let (Some((module, name)), Some(args)) = (p.global(func), p.seq(args)) else { return Ok(None) };
    if !module.starts_with("torch.") || depth > 4 {
        return Ok(None);
    }
    match (name, args) {
        ("_rebuild_tensor_v2", &[storage, offset, size, stride, ..]) => {
            strided(p, storage, offset, size, stride).map(Some)
        }
        // nn.Parameter and tensor subclasses wrap a plain tensor's rebuild.
        ("_rebuild_parameter" | "_rebuild_parameter_with_state", &[data, ..]) => rebuild(p, data, depth + 1),
        ("_rebuild_from_type_v2", &[func, _, args, ..]) => rebuild_call(p, func, args, depth + 1),
        _ => Ok(None),
    }
}

/// `_rebuild_tensor_v2(storage, storage_offset, size, stride, ...)`.
fn strided(p: &Pickle, storage: Id, offset: Id, size: Id, stride: Id) -> Parsed<Tensor> {
    let Obj::PersId(pid) = p.objs[storage] else { return Err(format!("its storage is {}", p.describe(storage))) };
    // ('storage', storage type, key, location, numel), and a view (always None since torch 0.4) in the legacy format.
    let Some(&[tag, storage_type, key, _, _, ref view @ ..]) = p.seq(pid) else {
        return Err("its storage's persistent id is not a tuple ('storage', type, key, location, numel)".into());
    };
    let key = p
        .str(key)
        .filter(|_| p.str(tag) == Some("storage"))
        .ok_or("its storage's persistent id is not ('storage', type, key, ...)")?;
    if view.first().is_some_and(|&v| !matches!(p.objs[v], Obj::None)) {
        return Err(
            "it views part of a storage, as torch < 0.4 saved; re-save the checkpoint with a newer torch".into()
        );
    }
    let (module, name) =
        p.global(storage_type).ok_or_else(|| format!("its storage type is {}", p.describe(storage_type)))?;
    let dtype = Dtype::from_global(module, name)
        .ok_or_else(|| format!("its storage type {module}.{name} is not one vkdiff knows"))?;
    let count = |id: Id| p.int(id).and_then(|v| usize::try_from(v).ok());
    let dims = |id: Id, what: &str| {
        p.seq(id)
            .and_then(|items| items.iter().map(|&d| count(d)).collect::<Option<Vec<_>>>())
            .ok_or_else(|| format!("its {what} is not a tuple of non-negative ints"))
    };
    let (shape, stride) = (dims(size, "size")?, dims(stride, "stride")?);
    if shape.len() != stride.len() {
        return Err(format!("size {shape:?} and stride {stride:?} differ in length"));
    }
    let offset = count(offset).ok_or("its storage offset is not a non-negative int")?;
    Ok(Tensor { dtype, shape, stride, offset, key: key.to_owned(), bytes: 0..0 })
}

/// Checks that every element of every tensor lies inside its storage, so `values` can index without checks, and that no
/// tensor is absurdly larger than the file (a broadcast view may repeat elements, a forged size may claim billions).
fn check(tensors: BTreeMap<String, Tensor>, file_len: usize) -> Parsed<BTreeMap<String, Tensor>> {
    for (name, t) in &tensors {
        let size = t.dtype.size();
        if t.bytes.len() % size != 0 {
            return Err(format!(
                "tensor `{name}`: its storage holds {} bytes, not a whole number of {size}-byte elements",
                t.bytes.len()
            ));
        }
        let elements = t.bytes.len() / size;
        let numel = t.shape.iter().try_fold(1usize, |n, &d| n.checked_mul(d)).filter(|&n| n <= elements.max(file_len));
        let numel = numel.ok_or_else(|| format!("tensor `{name}`: shape {:?} is too large for the file", t.shape))?;
        let last = t
            .shape
            .iter()
            .zip(&t.stride)
            .try_fold(t.offset, |at, (&d, &s)| at.checked_add(d.saturating_sub(1).checked_mul(s)?));
        if numel > 0 && last.is_none_or(|last| last >= elements) {
            return Err(format!(
                "tensor `{name}`: shape {:?}, stride {:?} and offset {} reach past its storage of {elements} elements",
                t.shape, t.stride, t.offset
            ));
        }
    }
    Ok(tensors)
}

#[cfg(test)]
mod tests {
    use super::*;

    const FIXTURES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/fixtures/pth/");

    fn fixture(name: &str) -> Vec<u8> {
        std::fs::read(format!("{FIXTURES}{name}")).unwrap()
    }

    fn parse(data: Vec<u8>) -> Result<TorchPth> {
        TorchPth::parse(PathBuf::from("test.pth"), data)
    }

    #[test]
    fn every_truncation_is_refused() {
        for file in ["zip.pth", "legacy.pth", "module.pth"] {
            let data = fixture(file);
            for len in 0..data.len() {
                assert!(matches!(parse(data[..len].to_vec()), Err(Error::Format { .. })), "{file} cut to {len} bytes");
            }
        }
    }

    #[test]
    fn garbled_bytes_never_panic() {
        for file in ["zip.pth", "legacy.pth", "zip-proto4.pth"] {
            let data = fixture(file);
            for at in 0..data.len() {
                for garble in [0xff, 0x80, 0x01] {
                    let mut bad = data.clone();
                    bad[at] ^= garble;
                    if let Ok(pth) = parse(bad) {
                        pth.names().iter().for_each(|name| drop(pth.values(name)));
                    }
                }
            }
        }
    }

    #[test]
    fn reads_the_classic_end_record_without_zip64() {
        let data = fixture("zip.pth");
        let eocd = data.len() - 22;
        // Torch writes a 56-byte zip64 record and a 20-byte locator before the classic record; drop both.
        let classic = [&data[..eocd - 76], &data[eocd..]].concat();
        let (a, b) = (parse(data).unwrap(), parse(classic).unwrap());
        assert_eq!(a.names(), b.names());
        assert_eq!(a.values("transposed").unwrap(), b.values("transposed").unwrap());
    }

    #[test]
    fn refuses_compressed_entries_and_big_endian_files() {
        let mut data = fixture("zip.pth");
        let byteorder = data.windows(6).position(|w| w == b"little").unwrap();
        data[byteorder..byteorder + 6].copy_from_slice(b"big\0\0\0");
        assert!(parse(data).err().unwrap().to_string().contains("byte order `big"));

        let mut data = fixture("zip.pth");
        let cd = data.windows(4).position(|w| w == b"PK\x01\x02").unwrap();
        data[cd + 10] = 8; // deflate
        assert!(parse(data).err().unwrap().to_string().contains("compressed"));
    }
}
