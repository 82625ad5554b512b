//! Surface normals from planar depth and the camera, as the normal ControlNets read them
//! (ControlNet 1.1's protocol, ScanNet's: red is left, green is up, blue faces the viewer; each
//! component c in [-1, 1] stored as ⌊(c + 1) / 2 · 255⌋, as the BAE annotator stores it), or
//! from the renderer's own normals where the scene gives them.

use crate::camera::Camera;

/// A pinhole camera's intrinsics in the image's pixels; integer coordinates are pixel centres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Intrinsics {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

impl Intrinsics {
    pub fn of(camera: &Camera) -> Intrinsics {
        Intrinsics { fx: camera.fx, fy: camera.fy, cx: camera.cx, cy: camera.cy }
    }

    /// Blender's default camera (a 50 mm lens on a 36 mm sensor spanning the longer side), for
    /// frames that come without one.
    pub fn blender_default(width: u32, height: u32) -> Intrinsics {
        let f = 50.0 / 36.0 * width.max(height) as f64;
        Intrinsics { fx: f, fy: f, cx: (width as f64 - 1.0) / 2.0, cy: (height as f64 - 1.0) / 2.0 }
    }
}

/// The colour of a pixel whose normal is unknown (background, a pixel alone on its surface):
/// facing the viewer.
pub const FACING: [u8; 3] = [127, 127, 255];

/// RGB8 normals of a `width`-wide frame. Where `given` (the renderer's normals, as
/// [`crate::frame::Frame::normals`] holds them: camera space, OpenCV axes, any length) has a
/// finite, non-zero normal for a pixel of finite depth, that normal, turned into (left, up,
/// toward the viewer) and made unit length. Elsewhere each pixel's camera-space point from its
/// depth, its tangents from the neighbours on its own surface (same id, depth within
/// `depth_jump`, as the edges define it: central differences, else one-sided), the normal their
/// cross product. Pixels of infinite depth face the viewer.
pub fn normal_image(
    ids: &[u16],
    depth: &[f32],
    given: Option<&[[f32; 3]]>,
    width: usize,
    camera: Intrinsics,
    depth_jump: f32,
) -> Vec<u8> {
    let height = ids.len().checked_div(width).unwrap_or(0);
    let point = |x: usize, y: usize| {
        let z = depth[y * width + x] as f64;
        [(x as f64 - camera.cx) / camera.fx * z, (y as f64 - camera.cy) / camera.fy * z, z]
    };
    let same = |p: usize, q: usize| {
        let (a, b) = (depth[p], depth[q]);
        ids[p] == ids[q] && a.is_finite() && b.is_finite() && (a - b).abs() <= depth_jump * a.min(b)
    };
    let mut out = Vec::with_capacity(ids.len() * 3);
    for y in 0..height {
        for x in 0..width {
            let p = y * width + x;
            let tangent = |before: Option<(usize, usize)>, after: Option<(usize, usize)>| {
                let on = |n: Option<(usize, usize)>| n.filter(|&(nx, ny)| same(p, ny * width + nx));
                let (a, b) = match (on(before), on(after)) {
                    (Some(a), Some(b)) => (a, b),
                    (None, Some(b)) => ((x, y), b),
                    (Some(a), None) => (a, (x, y)),
                    (None, None) => return None,
                };
                let (pa, pb) = (point(a.0, a.1), point(b.0, b.1));
                Some([pb[0] - pa[0], pb[1] - pa[1], pb[2] - pa[2]])
            };
            let from_depth = || {
                let along_x = tangent((x > 0).then(|| (x - 1, y)), (x + 1 < width).then(|| (x + 1, y)));
                let along_y = tangent((y > 0).then(|| (x, y - 1)), (y + 1 < height).then(|| (x, y + 1)));
                match (along_x, along_y) {
                    (Some(tx), Some(ty)) => encode(cross(tx, ty)).unwrap_or(FACING),
                    _ => FACING,
                }
            };
            let colour = if !depth[p].is_finite() {
                FACING
            } else {
                given.and_then(|n| rendered(n[p])).unwrap_or_else(from_depth)
            };
            out.extend_from_slice(&colour);
        }
    }
    out
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// The colour of a renderer's normal `n` (OpenCV axes: right, down, forward): (left, up, toward
/// the viewer) is −n. None for a zero or non-finite normal.
fn rendered(n: [f32; 3]) -> Option<[u8; 3]> {
    let e = n.map(|c| -(c as f64));
    e.iter().all(|c| c.is_finite()).then(|| encode(e)).flatten()
}

/// The colour of `e`, the normal in (left, up, toward the viewer) coordinates up to its length:
/// tangents along +x and +y (OpenCV's right and down) cross into exactly that for a surface that
/// faces the camera. None for a zero vector.
fn encode(e: [f64; 3]) -> Option<[u8; 3]> {
    let length = (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt();
    (length > 0.0).then(|| e.map(|c| ((c / length + 1.0) * 0.5 * 255.0).clamp(0.0, 255.0) as u8))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_wall_faces_the_viewer_and_a_floor_is_green() {
        let camera = Intrinsics { fx: 10.0, fy: 10.0, cx: 1.0, cy: 1.0 };
        let wall = normal_image(&[1; 9], &[2.0; 9], None, 3, camera, 0.05);
        assert!(wall.chunks(3).all(|px| px == FACING), "{wall:?}");
        // A floor 1 m below the camera, seen looking ahead: depth 10 / (y - cy) rows below the horizon.
        let (w, h) = (3usize, 3usize);
        let horizon = Intrinsics { fx: 10.0, fy: 10.0, cx: 1.0, cy: -1.0 };
        let depth: Vec<f32> = (0..w * h).map(|p| (10.0 / ((p / w) as f64 + 1.0)) as f32).collect();
        let floor = normal_image(&[1; 9], &depth, None, w, horizon, 1.0);
        assert_eq!(&floor[12..15], &[127, 255, 127], "{floor:?}");
        assert_eq!(normal_image(&[0], &[f32::INFINITY], None, 1, camera, 0.05), FACING);
    }

    #[test]
    fn the_renderers_normals_are_turned_and_unknown_ones_come_from_the_depth() {
        let camera = Intrinsics { fx: 10.0, fy: 10.0, cx: 1.0, cy: 0.0 };
        // A wall at 2 m: facing the viewer from its depth. The renderer says: facing up (OpenCV
        // −y), facing right, unknown (zero), unknown (NaN), and something for the sky.
        let given = [[0.0, -2.0, 0.0], [1.0, 0.0, 0.0], [0.0; 3], [f32::NAN, 0.0, -1.0], [0.0, 0.0, -1.0]];
        let mut depth = [2.0f32; 5];
        depth[4] = f32::INFINITY;
        let image = normal_image(&[1, 1, 1, 1, 0], &depth, Some(&given), 5, camera, 0.05);
        let pixels: Vec<&[u8]> = image.chunks(3).collect();
        assert_eq!(pixels, [&[127, 255, 127][..], &[0, 127, 127], &FACING, &FACING, &FACING]);
        assert_eq!(normal_image(&[1, 1, 1, 1, 0], &depth, None, 5, camera, 0.05), FACING.repeat(5));
        // A slope, 3×3: the depth's normals where the renderer's are zero or not finite.
        let slope: Vec<f32> = (0..9).map(|p| 2.0 + 0.5 * (p % 3) as f32).collect();
        let unknown = [[0.0, 0.0, 0.0], [f32::NAN, 0.0, 0.0], [0.0, f32::INFINITY, 0.0]].repeat(3);
        let from_depth = normal_image(&[1; 9], &slope, None, 3, camera, 1.0);
        assert_eq!(normal_image(&[1; 9], &slope, Some(&unknown), 3, camera, 1.0), from_depth);
        assert!(
            from_depth.chunks(3).all(|px| px[0] < 64),
            "a slope going away to the right faces right: {from_depth:?}"
        );
    }
}
