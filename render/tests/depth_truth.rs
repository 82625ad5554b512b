//! Every mask pixel's depth is the depth of the surface it came from: a ray through the pixel
//! centre, intersected in world space with the mushroom's own triangles (Möller–Trumbore, f64),
//! an independent path from the rasterizer's fixed-point edge functions and 1/z planes. And no
//! other mushroom lies in front of the one a pixel is labelled with.

use vkdiff_render::camera::Camera;
use vkdiff_render::math::Vec3;
use vkdiff_render::scene::{Scene, SceneConfig};

/// Ray parameter where `origin + t·dir` meets the triangle's plane (Möller–Trumbore without
/// the inside test, which is done on screen, in pixels).
fn intersect(origin: Vec3, dir: Vec3, [a, b, c]: [Vec3; 3]) -> Option<f64> {
    let (e1, e2) = (b - a, c - a);
    let p = dir.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-18 {
        return None;
    }
    let q = (origin - a).cross(e1);
    let t = e2.dot(q) / det;
    (t > 0.0).then_some(t)
}

/// Signed distance in pixels from (u, v) to the edges of the screen triangle: positive inside.
fn edge_distance(screen: &[(f64, f64); 3], u: f64, v: f64) -> f64 {
    let area = (screen[1].0 - screen[0].0) * (screen[2].1 - screen[0].1)
        - (screen[1].1 - screen[0].1) * (screen[2].0 - screen[0].0);
    (0..3)
        .map(|i| {
            let (p, q) = (screen[i], screen[(i + 1) % 3]);
            let cross = (q.0 - p.0) * (v - p.1) - (q.1 - p.1) * (u - p.0);
            cross.signum() * area.signum() * cross.abs() / (q.0 - p.0).hypot(q.1 - p.1).max(1e-12)
        })
        .fold(f64::MAX, f64::min)
}

/// Vertices are snapped to 1/256 pixel, which moves a triangle's edges by less than 0.003
/// pixel: a centre that far outside may still be covered, and one more than ROBUST inside is
/// covered whatever the snapping did.
const SNAP_SLACK_PX: f64 = 0.004;
const ROBUST_PX: f64 = 0.01;

struct Hit {
    depth: f64,
    /// Distance inside the triangle's edges, pixels.
    margin: f64,
    triangle: [Vec3; 3],
}

/// A world-space triangle, its screen corners and screen bounds grown by a pixel.
struct Triangle {
    corners: [Vec3; 3],
    screen: [(f64, f64); 3],
    bounds: [f64; 4],
}

/// The triangles of one mushroom and their union's bounds.
struct Mushroom {
    triangles: Vec<Triangle>,
    bounds: [f64; 4],
}

fn mushroom(camera: &Camera, positions: &[Vec3], indices: &[[u32; 3]]) -> Mushroom {
    let mut all = [f64::MAX, f64::MAX, f64::MIN, f64::MIN];
    let triangles = indices
        .iter()
        .map(|t| {
            let corners = t.map(|i| positions[i as usize]);
            let screen = corners.map(|p| {
                let (u, v, _) = camera.project(p);
                (u, v)
            });
            let mut b = [f64::MAX, f64::MAX, f64::MIN, f64::MIN];
            for (u, v) in screen {
                b = [b[0].min(u - 1.0), b[1].min(v - 1.0), b[2].max(u + 1.0), b[3].max(v + 1.0)];
            }
            all = [all[0].min(b[0]), all[1].min(b[1]), all[2].max(b[2]), all[3].max(b[3])];
            Triangle { corners, screen, bounds: b }
        })
        .collect();
    Mushroom { triangles, bounds: all }
}

fn covers(b: &[f64; 4], u: f64, v: f64) -> bool {
    u >= b[0] && u <= b[2] && v >= b[1] && v <= b[3]
}

/// Hits of the ray through pixel (u, v) with the mushroom's triangles whose edges are at least
/// `margin` pixels away on the inside (negative: that far outside).
fn hits(camera: &Camera, u: f64, v: f64, m: &Mushroom, margin: f64) -> Vec<Hit> {
    let dir = camera.ray_direction(u, v);
    m.triangles
        .iter()
        .filter(|t| covers(&t.bounds, u, v))
        .filter_map(|t| {
            let inside = edge_distance(&t.screen, u, v);
            (inside >= margin).then_some(())?;
            intersect(camera.position, dir, t.corners).map(|depth| Hit { depth, margin: inside, triangle: t.corners })
        })
        .collect()
}

#[test]
fn mask_pixels_carry_the_depth_of_their_own_mushroom_and_nothing_is_in_front() {
    let config = SceneConfig::default(); // the paper's 1920×1080 frame
    let scene = Scene::build(11, &config).unwrap();
    let frame = scene.render();
    let cam = frame.camera.as_ref().expect("the bed's frames have their camera");
    let (w, h) = (frame.width(), frame.height());
    let meshes: Vec<Mushroom> = frame
        .instances
        .iter()
        .map(|info| {
            let bed_index = info.attributes["bed_index"].as_u64().unwrap() as usize;
            let variant = &scene.bed.variants[scene.bed.instances[bed_index].variant];
            mushroom(cam, &scene.bed.instance_positions(bed_index), &variant.mesh.triangles)
        })
        .collect();
    assert!(meshes.len() > 100, "{} visible mushrooms", meshes.len());

    let (mut checked, mut max_error, mut occluded) = (0usize, 0f64, 0usize);
    for y in 0..h {
        let v = y as f64;
        let in_row: Vec<usize> =
            (0..meshes.len()).filter(|&k| v >= meshes[k].bounds[1] && v <= meshes[k].bounds[3]).collect();
        for x in 0..w {
            let u = x as f64;
            let depth = frame.depth[y * w + x] as f64;
            let id = frame.ids[y * w + x] as usize;
            if id > 0 {
                // Near an edge the snapped raster may have used the neighbouring triangle: every
                // triangle within the snapping slack is a candidate, each judged by its own depth
                // slope (the snap moves the surface by at most slope/512; f32 storage adds about
                // 1e-7 m).
                let candidates = hits(cam, u, v, &meshes[id - 1], -SNAP_SLACK_PX);
                assert!(!candidates.is_empty(), "pixel ({x},{y}) labelled {id} misses that mushroom");
                let tolerance = |hit: &Hit| {
                    let plane_depth = |du: f64, dv: f64| {
                        intersect(cam.position, cam.ray_direction(u + du, v + dv), hit.triangle).unwrap_or(hit.depth)
                    };
                    3e-7 + ((plane_depth(1.0, 0.0) - hit.depth).abs() + (plane_depth(0.0, 1.0) - hit.depth).abs())
                        / 512.0
                };
                let error = candidates
                    .iter()
                    .filter_map(|hit| {
                        let error = (hit.depth - depth).abs();
                        (error <= tolerance(hit)).then_some(error)
                    })
                    .fold(None, |best: Option<f64>, e| Some(best.map_or(e, |b| b.min(e))))
                    .unwrap_or_else(|| {
                        panic!(
                            "pixel ({x},{y}) of {id}: raster depth {depth} m matches none of {:?}",
                            candidates.iter().map(|h| h.depth).collect::<Vec<_>>()
                        )
                    });
                max_error = max_error.max(error);
                // ... and it is the front surface: nothing of the same mushroom clearly in front.
                if let Some(front) =
                    candidates.iter().filter(|h| h.margin > ROBUST_PX).min_by(|a, b| a.depth.total_cmp(&b.depth))
                {
                    assert!(
                        depth <= front.depth + tolerance(front),
                        "pixel ({x},{y}) of {id} shows {depth} m behind its front surface at {} m",
                        front.depth
                    );
                }
                checked += 1;
            }
            // No other mushroom is clearly hit in front of what the pixel shows.
            for &k in &in_row {
                if k + 1 == id || !covers(&meshes[k].bounds, u, v) {
                    continue;
                }
                // Only hits well inside a triangle count: on an edge the snapped raster may
                // legitimately fall on either side.
                if let Some(front) = hits(cam, u, v, &meshes[k], ROBUST_PX).iter().map(|h| h.depth).reduce(f64::min) {
                    assert!(
                        front > depth - 1e-6,
                        "pixel ({x},{y}) shows {id} at {depth} m but {} is at {front} m",
                        k + 1
                    );
                    occluded += 1;
                }
            }
        }
    }
    assert!(checked > 200_000, "only {checked} mask pixels");
    assert!(occluded > 1_000, "only {occluded} hidden surfaces checked");
    eprintln!("{checked} mask pixels, largest depth difference {max_error:e} m; {occluded} hidden hits behind");
}
