//! Reading Replicator BasicWriter's files: the refusals that name them, their JSON, and the
//! headers of the depth and the instance image, checked before any pixel is read.

use crate::{bad, SceneError};
use std::io::BufReader;
use std::path::Path;

/// `why`, about `file` of frame `frame`, before the frames are listed.
pub(crate) fn refuse(frame: &str, file: &str, why: impl std::fmt::Display) -> SceneError {
    SceneError::new(format!("frame {frame}: {file}: {why}"))
}

/// A frame's JSON file, parsed.
pub(crate) fn read_json<T: serde::de::DeserializeOwned>(dir: &Path, frame: &str, name: &str) -> Result<T, SceneError> {
    let text = std::fs::read_to_string(dir.join(name)).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => refuse(frame, name, "missing"),
        _ => refuse(frame, name, e),
    })?;
    serde_json::from_str(&text).map_err(|e| refuse(frame, name, format!("not BasicWriter's format: {e}")))
}

fn open_file(dir: &Path, name: &str) -> Result<BufReader<std::fs::File>, SceneError> {
    let f = std::fs::File::open(dir.join(name)).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => bad(name, "missing"),
        _ => bad(name, e),
    })?;
    Ok(BufReader::new(f))
}

/// A .npy file, its header read.
pub(crate) type Npy = npyz::NpyFile<BufReader<std::fs::File>>;

/// The depth file's header: a 2-D float array; its width, height, and whether it is float64.
pub(crate) fn depth_header(dir: &Path, name: &str) -> Result<(Npy, usize, usize, bool), SceneError> {
    let npy = npyz::NpyFile::new(open_file(dir, name)?).map_err(|e| bad(name, format!("not a .npy file: {e}")))?;
    let &[rows, cols] = npy.shape() else {
        return Err(bad(name, format!("shape {:?}; distance_to_image_plane is H×W", npy.shape())));
    };
    match npy.dtype() {
        npyz::DType::Plain(t) if t.type_char() == npyz::TypeChar::Float && matches!(t.size_field(), 4 | 8) => {
            let double = t.size_field() == 8;
            Ok((npy, cols as usize, rows as usize, double))
        }
        npyz::DType::Plain(t) => Err(bad(name, format!("dtype {t}; distance_to_image_plane is float32"))),
        _ => Err(bad(name, "a structured array; distance_to_image_plane is float32")),
    }
}

/// The instance image's header: 8-bit RGBA, (width, height).
pub(crate) fn instance_header(dir: &Path, name: &str) -> Result<png::Reader<BufReader<std::fs::File>>, SceneError> {
    let reader =
        png::Decoder::new(open_file(dir, name)?).read_info().map_err(|e| bad(name, format!("bad PNG: {e}")))?;
    let info = reader.info();
    if (info.color_type, info.bit_depth) != (png::ColorType::Rgba, png::BitDepth::Eight) {
        let why = format!(
            "{:?} {:?}-bit, not 8-bit RGBA; only colorize_instance_segmentation=True (BasicWriter's default) is read",
            info.color_type, info.bit_depth as u8
        );
        return Err(bad(name, why));
    }
    Ok(reader)
}

/// Refuses `name` of `size` where the frame's depth is `depth`.
pub(crate) fn same_size(name: &str, size: (usize, usize), depth: (usize, usize)) -> Result<(), SceneError> {
    if size == depth {
        return Ok(());
    }
    Err(bad(name, format!("{}×{}, the frame's depth is {}×{}", size.0, size.1, depth.0, depth.1)))
}
