//! Readers for the files vkdiff-render writes, through independent implementations (the `exr`
//! and `png` crates), shared by the integration tests.
#![allow(dead_code)] // each test binary uses its own subset

use std::path::Path;

/// (width, height, channel name, values) of the first layer of an EXR file.
pub fn read_exr(bytes: &[u8]) -> (usize, usize, String, Vec<f32>) {
    use exr::prelude::*;
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_buffered(std::io::Cursor::new(bytes))
        .expect("the exr crate reads our file");
    let layer = image.layer_data;
    assert_eq!(layer.channel_data.list.len(), 1, "one channel");
    let channel = &layer.channel_data.list[0];
    let values = channel.sample_data.values_as_f32().collect();
    (layer.size.width(), layer.size.height(), channel.name.to_string(), values)
}

/// (width, height, color type, bit depth, samples) of a PNG; 16-bit samples are big-endian pairs.
pub fn read_png(path: &Path) -> (u32, u32, png::ColorType, png::BitDepth, Vec<u8>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    buf.truncate(info.buffer_size());
    (info.width, info.height, info.color_type, info.bit_depth, buf)
}

/// instances.png as ids.
pub fn read_ids(path: &Path) -> (u32, u32, Vec<u16>) {
    let (w, h, color, depth, bytes) = read_png(path);
    assert_eq!((color, depth), (png::ColorType::Grayscale, png::BitDepth::Sixteen));
    (w, h, bytes.chunks(2).map(|b| u16::from_be_bytes([b[0], b[1]])).collect())
}

/// A fresh, empty folder for one test under Cargo's scratch space.
pub fn scratch(name: &str) -> std::path::PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Every file below `dir`, by path relative to it.
pub fn read_tree(dir: &Path) -> std::collections::BTreeMap<String, Vec<u8>> {
    let mut files = std::collections::BTreeMap::new();
    let mut pending = vec![dir.to_path_buf()];
    while let Some(folder) = pending.pop() {
        for entry in std::fs::read_dir(&folder).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                pending.push(path);
            } else {
                let name = path.strip_prefix(dir).unwrap().to_string_lossy().into_owned();
                files.insert(name, std::fs::read(&path).unwrap());
            }
        }
    }
    files
}

pub fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}
