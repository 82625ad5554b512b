//! Metric depth in an OpenEXR file: the `exr` crate reads every compression OpenEXR tools write
//! (ZIP, PIZ, RLE, PXR24, B44, …).

use crate::{Error, Result};
use exr::prelude::{read_all_flat_layers_from_file, FlatImage, FlatSamples};
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
    let image = read_file(path)?;
    let channels = channels(&image);
    let names: Vec<String> = channels.iter().map(|c| c.0.clone()).collect();
    let (_, samples, width, height) = channels[pick(&names).map_err(format_error(path))?];
    Ok((floats(samples), width, height))
}

/// The normals' channels: `X`, `Y` and `Z`, all three, of one size.
pub(super) fn pick_normals(names: &[String], sizes: &[(usize, usize)]) -> std::result::Result<[usize; 3], String> {
    let find = |want: &str| names.iter().position(|n| n == want);
    let (Some(x), Some(y), Some(z)) = (find("X"), find("Y"), find("Z")) else {
        return Err(format!("no X, Y and Z channels (the camera-space normal); channels: {}", names.join(", ")));
    };
    if sizes[x] != sizes[y] || sizes[x] != sizes[z] {
        return Err(format!("X, Y and Z are {:?}, {:?} and {:?} pixels; one size", sizes[x], sizes[y], sizes[z]));
    }
    Ok([x, y, z])
}

/// The normals of an EXR file's `X`, `Y`, `Z` channels (row-major, as stored) and (width, height).
pub fn read_normals_exr(path: &Path) -> Result<(Vec<[f32; 3]>, usize, usize)> {
    let image = read_file(path)?;
    let channels = channels(&image);
    let names: Vec<String> = channels.iter().map(|c| c.0.clone()).collect();
    let sizes: Vec<(usize, usize)> = channels.iter().map(|c| (c.2, c.3)).collect();
    let [x, y, z] = pick_normals(&names, &sizes).map_err(format_error(path))?;
    let [xs, ys, zs] = [x, y, z].map(|k| floats(channels[k].1));
    let normals = xs.iter().zip(&ys).zip(&zs).map(|((&x, &y), &z)| [x, y, z]).collect();
    Ok((normals, sizes[x].0, sizes[x].1))
}

/// The `R`, `G` and `B` channels of an EXR file (row-major, as stored) and (width, height): what a
/// renderer that stores vectors as colour writes (Unity Perception's normals).
pub fn read_rgb_exr(path: &Path) -> Result<(Vec<[f32; 3]>, usize, usize)> {
    let image = read_file(path)?;
    let channels = channels(&image);
    let find = |want: &str| channels.iter().position(|c| c.0 == want);
    let (Some(r), Some(g), Some(b)) = (find("R"), find("G"), find("B")) else {
        let names: Vec<&str> = channels.iter().map(|c| c.0.as_str()).collect();
        return Err(format_error(path)(format!("no R, G and B channels; channels: {}", names.join(", "))));
    };
    let size = (channels[r].2, channels[r].3);
    if [g, b].iter().any(|&k| (channels[k].2, channels[k].3) != size) {
        return Err(format_error(path)("R, G and B differ in size".into()));
    }
    let [rs, gs, bs] = [r, g, b].map(|k| floats(channels[k].1));
    let values = rs.iter().zip(&gs).zip(&bs).map(|((&r, &g), &b)| [r, g, b]).collect();
    Ok((values, size.0, size.1))
}

fn format_error(path: &Path) -> impl Fn(String) -> Error + '_ {
    move |why| Error::Format { path: path.to_path_buf(), why }
}

fn read_file(path: &Path) -> Result<FlatImage> {
    read_all_flat_layers_from_file(path).map_err(|e| format_error(path)(format!("bad OpenEXR file: {e}")))
}

/// Every channel of every part, named `<part>.<channel>` for named parts, with its samples and its
/// part's (width, height).
fn channels(image: &FlatImage) -> Vec<(String, &FlatSamples, usize, usize)> {
    let mut found = Vec::new();
    for layer in &image.layer_data {
        let prefix = layer.attributes.layer_name.as_ref().map(|n| format!("{n}."));
        for channel in &layer.channel_data.list {
            let name = format!("{}{}", prefix.as_deref().unwrap_or(""), channel.name);
            found.push((name, &channel.sample_data, layer.size.0, layer.size.1));
        }
    }
    found
}

fn floats(samples: &FlatSamples) -> Vec<f32> {
    match samples {
        FlatSamples::F32(v) => v.clone(),
        FlatSamples::F16(v) => v.iter().map(|h| h.to_f32()).collect(),
        FlatSamples::U32(v) => v.iter().map(|&u| u as f32).collect(),
    }
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

    #[test]
    fn normals_are_x_y_z_of_one_size() {
        let names = |n: &[&str]| n.iter().map(|n| n.to_string()).collect::<Vec<_>>();
        let pick = super::pick_normals;
        assert_eq!(pick(&names(&["Z", "Y", "X"]), &[(4, 3); 3]), Ok([2, 1, 0]));
        assert!(pick(&names(&["R", "G", "B"]), &[(4, 3); 3]).unwrap_err().contains("channels: R, G, B"));
        assert!(pick(&names(&["X", "Y", "Z"]), &[(4, 3), (4, 3), (2, 3)]).unwrap_err().contains("one size"));
    }
}
