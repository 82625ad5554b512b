//! Metric depth in an OpenEXR file: the `exr` crate reads every compression OpenEXR tools write
//! (ZIP, PIZ, RLE, PXR24, B44, …).

use crate::{Error, Result};
use exr::prelude::{read_all_flat_layers_from_file, FlatSamples};
use std::path::Path;

/// The depth channel: `Z`; else one `Depth.Z` or `<layer>.Depth.Z` (Blender's multilayer
/// files); else `V`; else `R`. Several Depth.Z layers, or none of these, is an error.
pub(super) fn pick(names: &[String]) -> std::result::Result<usize, String> {
    let find = |want: &str| names.iter().position(|n| n == want);
    if let Some(i) = find("Z") {
        return Ok(i);
    }
    let depth: Vec<usize> =
        (0..names.len()).filter(|&i| names[i] == "Depth.Z" || names[i].ends_with(".Depth.Z")).collect();
    match depth.len() {
        1 => return Ok(depth[0]),
        0 => {}
        _ => {
            let list: Vec<&str> = depth.iter().map(|&i| names[i].as_str()).collect();
            return Err(format!("several depth layers ({}); keep one", list.join(", ")));
        }
    }
    find("V")
        .or_else(|| find("R"))
        .ok_or_else(|| format!("no depth channel (Z, <layer>.Depth.Z, V or R); channels: {}", names.join(", ")))
}

/// Depth values (row-major) and (width, height) of the depth channel of an EXR file.
pub fn read_depth_exr(path: &Path) -> Result<(Vec<f32>, usize, usize)> {
    let fail = |why: String| Error::Format { path: path.to_path_buf(), why };
    let image = read_all_flat_layers_from_file(path).map_err(|e| fail(format!("bad OpenEXR file: {e}")))?;
    // Every channel of every part, named `<part>.<channel>` for named parts.
    let mut names = Vec::new();
    let mut found = Vec::new();
    for layer in &image.layer_data {
        let prefix = layer.attributes.layer_name.as_ref().map(|n| format!("{n}."));
        for channel in &layer.channel_data.list {
            names.push(format!("{}{}", prefix.as_deref().unwrap_or(""), channel.name));
            found.push((&channel.sample_data, layer.size.0, layer.size.1));
        }
    }
    let (samples, width, height) = found[pick(&names).map_err(fail)?];
    let values: Vec<f32> = match samples {
        FlatSamples::F32(v) => v.clone(),
        FlatSamples::F16(v) => v.iter().map(|h| h.to_f32()).collect(),
        FlatSamples::U32(v) => v.iter().map(|&u| u as f32).collect(),
    };
    Ok((values, width, height))
}

#[cfg(test)]
mod tests {
    #[test]
    fn depth_is_z_then_one_depth_layer_then_v_then_r() {
        let pick = |names: &[&str]| super::pick(&names.iter().map(|n| n.to_string()).collect::<Vec<_>>());
        assert_eq!(pick(&["R", "G", "B", "Z"]), Ok(3));
        assert_eq!(pick(&["R", "View.Depth.Z"]), Ok(1));
        assert_eq!(pick(&["Depth.Z", "V"]), Ok(0));
        assert_eq!(pick(&["R", "V"]), Ok(1));
        assert_eq!(pick(&["G", "R"]), Ok(1));
        assert!(pick(&["A.Depth.Z", "B.Depth.Z", "Z"]).is_ok(), "Z comes before the layers");
        assert!(pick(&["A.Depth.Z", "B.Depth.Z"]).unwrap_err().contains("several depth layers"));
        assert!(pick(&["A", "Y"]).unwrap_err().contains("channels: A, Y"));
    }
}
