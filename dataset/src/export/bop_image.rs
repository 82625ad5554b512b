//! One image of a BOP export: its render linked into `rgb/`, its depth as a 16-bit PNG, a visible
//! mask (and an amodal one) per gt, and its entries of scene_camera.json, scene_gt.json and
//! scene_gt_info.json.

use super::set::{FinishedSet, SetImage};
use super::staging::Staging;
use crate::error::{Error, Result};
use serde_json::{json, Value};
use vkdiff_formats::image::{read_depth_exr, read_grey_png};
use vkdiff_render::geometry::ObjectPose;
use vkdiff_render::png_out::{gray16, gray8};
use vkdiff_render::rle::Rle;

/// Depth steps tried in turn, in mm: 0.1 mm as BOP's PBR training sets store depth (to 6.55 m);
/// an image whose farthest depth does not fit takes the next.
const DEPTH_SCALES: [f64; 3] = [0.1, 1.0, 10.0];

/// What an image gives its scene's JSON files.
pub struct BopImage {
    pub camera: Value,
    pub gts: Vec<Value>,
    pub infos: Vec<Value>,
    /// Instances whose whole shape the set does not hold: their silhouette is the visible mask.
    pub without_amodal: u64,
    /// Whether its depth took a step coarser than 0.1 mm.
    pub coarse_depth: bool,
}

/// Where a scene's files go: `{split}/{scene:06}`, and whether it has `mask/`.
pub struct SceneFolder {
    pub path: String,
    pub amodal: bool,
}

/// Writes image `im_id` of `scene`.
pub fn write(
    set: &FinishedSet,
    image: &SetImage,
    scene: &SceneFolder,
    im_id: usize,
    staging: &mut Staging,
) -> Result<BopImage> {
    let (width, height) = (image.entry["width"].as_u64().unwrap_or(0), image.entry["height"].as_u64().unwrap_or(0));
    let (w, h) = (width as usize, height as usize);
    let id = &image.entry["id"];
    let bad = |why: String| Error::Config(format!("image {id}: {why}"));
    let name = image.file_name();
    let extension = name.rsplit('.').next().unwrap_or("png");
    staging.link(&set.dir.join(name), &format!("{}/rgb/{im_id:06}.{extension}", scene.path))?;

    let file = |key: &str| image.entry[key].as_str().ok_or_else(|| bad(format!("no {key}")));
    let ids = read_grey_png(&set.dir.join(file("mask_file")?))?;
    let (metres, dw, dh) = read_depth_exr(&set.dir.join(file("depth_file")?))?;
    if (ids.width, ids.height) != (w, h) || (dw, dh) != (w, h) {
        return Err(bad(format!("its mask ({}×{}) or depth ({dw}×{dh}) is not {w}×{h}", ids.width, ids.height)));
    }
    let (steps, depth_scale) = depth_steps(&metres);
    staging.write(&format!("{}/depth/{im_id:06}.png", scene.path), &gray16(width as u32, height as u32, &steps))?;

    let mut written = BopImage {
        camera: camera_entry(&image.entry["camera"], depth_scale).ok_or_else(|| bad("no camera K".into()))?,
        gts: Vec::new(),
        infos: Vec::new(),
        without_amodal: 0,
        coarse_depth: depth_scale > DEPTH_SCALES[0],
    };
    for (gt_id, a) in image.annotations.iter().enumerate() {
        let at = |why: String| bad(format!("annotation {}: {why}", a["id"]));
        let mask_id = a["mask_id"].as_u64().ok_or_else(|| at("no mask_id".into()))?;
        let visible: Vec<bool> = ids.values.iter().map(|&v| v as u64 == mask_id).collect();
        let area = visible.iter().filter(|&&v| v).count() as u64;
        if Some(area) != a["area"].as_u64() {
            return Err(at(format!("the mask holds {area} pixels of it, its area is {}", a["area"])));
        }
        let whole = match amodal_mask(a, width, height).map_err(at)? {
            Some(mask) => mask,
            None => {
                written.without_amodal += 1;
                visible.clone()
            }
        };
        let files = [("mask_visib", Some(&visible)), ("mask", scene.amodal.then_some(&whole))];
        for (folder, mask) in files {
            if let Some(mask) = mask {
                let pixels: Vec<u8> = mask.iter().map(|&on| if on { 255 } else { 0 }).collect();
                let png = gray8(width as u32, height as u32, &pixels);
                staging.write(&format!("{}/{folder}/{im_id:06}_{gt_id:06}.png", scene.path), &png)?;
            }
        }
        written.infos.push(gt_info(&visible, &whole, &steps, w));
        let pose = a.as_object().and_then(ObjectPose::of).ok_or_else(|| at("no pose".into()))?;
        written.gts.push(json!({
            "cam_R_m2c": pose.r.concat(),
            "cam_t_m2c": pose.t.map(|m| m * 1000.0),
            "obj_id": a["category_id"],
        }));
    }
    Ok(written)
}

/// The depth in steps of the finest scale that holds its farthest point, rounded half to even
/// and clipped at 65535 as BOP's `save_depth` (BlenderProc's) stores it; no depth is 0.
fn depth_steps(metres: &[f32]) -> (Vec<u16>, f64) {
    let far = metres.iter().filter(|z| z.is_finite() && **z > 0.0).fold(0.0f64, |m, &z| m.max(z as f64));
    let fits = |scale: &&f64| (far * 1000.0 / **scale).round_ties_even() <= u16::MAX as f64;
    let scale = *DEPTH_SCALES.iter().find(fits).unwrap_or(&DEPTH_SCALES[DEPTH_SCALES.len() - 1]);
    let step = |z: f32| match z.is_finite() && z > 0.0 {
        true => (z as f64 * 1000.0 / scale).round_ties_even().min(u16::MAX as f64) as u16,
        false => 0,
    };
    (metres.iter().map(|&z| step(z)).collect(), scale)
}

/// scene_camera.json's entry: cam_K, depth_scale, and the world's pose in the camera (mm) where
/// the set knows the camera's.
fn camera_entry(camera: &Value, depth_scale: f64) -> Option<Value> {
    let k: [[f64; 3]; 3] = serde_json::from_value(camera["K"].clone()).ok()?;
    let mut entry = json!({"cam_K": k.concat(), "depth_scale": depth_scale});
    if let Ok(t) = serde_json::from_value::<[[f64; 4]; 4]>(camera["T_world_camera_opencv"].clone()) {
        // T_world_camera = [R | c]; the world in the camera is [Rᵀ | −Rᵀc].
        let r_w2c: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| t[j][i]));
        let t_w2c: [f64; 3] = std::array::from_fn(|i| -(0..3).map(|j| t[j][i] * t[j][3]).sum::<f64>() * 1000.0);
        entry["cam_R_w2c"] = json!(r_w2c.concat());
        entry["cam_t_w2c"] = json!(t_w2c);
    }
    Some(entry)
}

/// The annotation's amodal mask, row-major; None where it has none.
fn amodal_mask(a: &Value, width: u64, height: u64) -> std::result::Result<Option<Vec<bool>>, String> {
    let s = &a["amodal_segmentation"];
    if s.is_null() {
        return Ok(None);
    }
    let counts = s["counts"].as_str().ok_or("amodal_segmentation is not a COCO RLE mask")?;
    if s["size"] != json!([height, width]) {
        return Err(format!("amodal_segmentation's size {} is not [{height}, {width}]", s["size"]));
    }
    let rle = Rle::from_coco_string(counts, height as u32, width as u32).map_err(|e| e.to_string())?;
    Ok(Some(rle.to_mask()))
}

/// scene_gt_info.json's entry, as bop_toolkit's calc_gt_info defines its fields, from the set's
/// masks: the silhouette is the whole (amodal) mask within the image, the visible part the
/// visible mask; boxes by `misc.calc_2d_bbox` ([x, y, max x − x, max y − y]).
fn gt_info(visible: &[bool], whole: &[bool], depth: &[u16], width: usize) -> Value {
    let all = whole.iter().filter(|&&v| v).count();
    let visib = visible.iter().filter(|&&v| v).count();
    let valid = whole.iter().zip(depth).filter(|(&v, &d)| v && d > 0).count();
    json!({
        "bbox_obj": bop_box(whole, width),
        "bbox_visib": bop_box(visible, width),
        "px_count_all": all,
        "px_count_valid": valid,
        "px_count_visib": visib,
        "visib_fract": if all > 0 { visib as f64 / all as f64 } else { 0.0 },
    })
}

/// calc_2d_bbox of the mask's pixels; [-1, -1, -1, -1] for none, as calc_gt_info writes it.
fn bop_box(mask: &[bool], width: usize) -> [i64; 4] {
    let pixels = mask.iter().enumerate().filter(|(_, &v)| v).map(|(p, _)| ((p % width) as i64, (p / width) as i64));
    let extent = pixels.fold(None, |b: Option<[i64; 4]>, (x, y)| {
        Some(b.map_or([x, y, x, y], |[x0, y0, x1, y1]| [x0.min(x), y0.min(y), x1.max(x), y1.max(y)]))
    });
    extent.map_or([-1; 4], |[x0, y0, x1, y1]| [x0, y0, x1 - x0, y1 - y0])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth_takes_the_finest_scale_that_holds_it_rounding_half_to_even() {
        let (steps, scale) = depth_steps(&[0.5, f32::INFINITY, 0.0, -1.0, 6.5]);
        assert_eq!(scale, 0.1);
        assert_eq!(steps, [5000, 0, 0, 0, 65000]);
        let (steps, scale) = depth_steps(&[7.0, 0.00015]);
        assert_eq!((scale, steps[0]), (1.0, 7000));
        // 0.15 mm in 1 mm steps: 0.15 rounds to 0 (and no depth is 0 as well).
        assert_eq!(steps[1], 0);
        let (steps, scale) = depth_steps(&[1e4, 1.0]);
        assert_eq!((scale, steps), (10.0, vec![u16::MAX, 100]), "beyond the coarsest scale: clipped");
    }

    #[test]
    fn boxes_span_first_to_last_pixel_as_calc_2d_bbox_does() {
        let (w, h) = (5, 4);
        let mask: Vec<bool> = (0..w * h).map(|p| (1..4).contains(&(p % w)) && (2..4).contains(&(p / w))).collect();
        assert_eq!(bop_box(&mask, w), [1, 2, 2, 1]);
        assert_eq!(bop_box(&[false; 6], 3), [-1; 4]);
        let whole: Vec<bool> = (0..w * h).map(|p| p / w >= 1).collect();
        let depth: Vec<u16> = (0..w * h).map(|p| if p % w == 0 { 0 } else { 9 }).collect();
        let info = gt_info(&mask, &whole, &depth, w);
        assert_eq!(info["px_count_all"], 15);
        assert_eq!(info["px_count_valid"], 12, "pixels of the silhouette with depth");
        assert_eq!(info["px_count_visib"], 6);
        assert_eq!(info["visib_fract"], 6.0 / 15.0);
    }

    #[test]
    fn the_world_pose_in_the_camera_inverts_the_cameras_pose_in_the_world() {
        // Camera at (1, 2, 3) m, turned 90° about z.
        let t = [[0.0, -1.0, 0.0, 1.0], [1.0, 0.0, 0.0, 2.0], [0.0, 0.0, 1.0, 3.0], [0.0, 0.0, 0.0, 1.0]];
        let camera = json!({"K": [[50.0, 0.0, 10.0], [0.0, 50.0, 8.0], [0.0, 0.0, 1.0]], "T_world_camera_opencv": t});
        let entry = camera_entry(&camera, 0.1).unwrap();
        let r: Vec<f64> = serde_json::from_value(entry["cam_R_w2c"].clone()).unwrap();
        let tw: Vec<f64> = serde_json::from_value(entry["cam_t_w2c"].clone()).unwrap();
        // The camera's centre, in mm, maps to the camera's origin.
        let centre = [1000.0, 2000.0, 3000.0];
        for i in 0..3 {
            let x: f64 = (0..3).map(|j| r[3 * i + j] * centre[j]).sum::<f64>() + tw[i];
            assert!(x.abs() < 1e-9, "{x}");
        }
        assert_eq!(entry["cam_K"], json!([50.0, 0.0, 10.0, 0.0, 50.0, 8.0, 0.0, 0.0, 1.0]));
        let unknown = camera_entry(&json!({"K": camera["K"], "T_world_camera_opencv": null}), 1.0).unwrap();
        assert!(unknown.get("cam_R_w2c").is_none() && unknown["depth_scale"] == 1.0);
        assert!(camera_entry(&json!({}), 0.1).is_none());
    }
}
