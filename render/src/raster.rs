//! A z-buffer triangle rasterizer producing planar depth and an instance id per pixel.
//!
//! - Pixel centres are the integer coordinates (OpenCV); a pixel belongs to a triangle when its
//!   centre lies inside, with the top-left rule on shared edges.
//! - Vertices are snapped to 1/256 pixel and edge functions are evaluated in exact integer
//!   arithmetic, so meshes are watertight: no pixel is drawn twice or missed along a shared edge.
//! - Depth is perspective-correct: 1/z is linear in screen space, so the rasterizer interpolates
//!   1/z and stores z = 1/(1/z). The z-test keeps the nearest surface; on an exact tie the
//!   triangle submitted first wins, which keeps the result independent of scheduling.
//! - The image is cut into bands of rows, rasterized in parallel; each band draws its triangles
//!   in submission order, so the output is byte-identical for any number of threads.
//! - Back faces are culled: meshes are closed or seen from their front (the ground).

use rayon::prelude::*;

use crate::camera::Camera;
use crate::math::Vec3;

const SUBPIXEL_BITS: u32 = 8;
const ONE: i64 = 1 << SUBPIXEL_BITS;
const BAND_ROWS: usize = 32;
/// Nothing closer than this to the camera is drawn (the scene never comes near it).
const NEAR_M: f64 = 1e-3;

/// A front-facing triangle in screen space, clockwise on the y-down screen.
#[derive(Clone, Copy, Debug)]
pub struct ScreenTriangle {
    /// Fixed-point vertex coordinates.
    x: [i64; 3],
    y: [i64; 3],
    /// Inclusive pixel bounds, clipped to the image.
    px: (u32, u32),
    py: (u32, u32),
    /// 1/z at pixel (px.0, py.0) and its steps per pixel in x and y.
    inv_z: f64,
    inv_z_dx: f64,
    inv_z_dy: f64,
    id: u32,
}

/// Depth (metres, +∞ where nothing was drawn) and id (0 where nothing was drawn) per pixel,
/// row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct RasterImage {
    pub width: u32,
    pub height: u32,
    pub depth: Vec<f32>,
    pub ids: Vec<u32>,
}

/// Projects a world-space mesh and sets up its visible triangles, tagged with `id`.
pub fn project_mesh(camera: &Camera, positions: &[Vec3], triangles: &[[u32; 3]], id: u32, out: &mut Vec<ScreenTriangle>) {
    let projected: Vec<Option<(i64, i64, f64)>> = positions
        .iter()
        .map(|&p| {
            let (u, v, z) = camera.project(p);
            // A bound far outside any image keeps the fixed-point products inside i64.
            let inside = z > NEAR_M && u.abs() < 1e6 && v.abs() < 1e6;
            inside.then(|| ((u * ONE as f64).round() as i64, (v * ONE as f64).round() as i64, 1.0 / z))
        })
        .collect();
    for tri in triangles {
        let [Some(a), Some(b), Some(c)] = tri.map(|i| projected[i as usize]) else { continue };
        // Counter-clockwise in the world is counter-clockwise on screen, i.e. negative doubled
        // area in y-down coordinates; swapping two vertices makes it clockwise-positive.
        if let Some(t) = setup(camera, a, c, b, id) {
            out.push(t);
        }
    }
}

/// Doubled signed area of the edge p→q against point s; positive on the inside of a clockwise
/// (y-down) triangle.
fn edge(p: (i64, i64), q: (i64, i64), s: (i64, i64)) -> i64 {
    (q.0 - p.0) * (s.1 - p.1) - (q.1 - p.1) * (s.0 - p.0)
}

fn setup(camera: &Camera, a: (i64, i64, f64), b: (i64, i64, f64), c: (i64, i64, f64), id: u32) -> Option<ScreenTriangle> {
    let (pa, pb, pc) = ((a.0, a.1), (b.0, b.1), (c.0, c.1));
    let area = edge(pa, pb, pc);
    if area <= 0 {
        return None; // back-facing or degenerate
    }
    let ceil_px = |v: i64| (v + ONE - 1).div_euclid(ONE);
    let floor_px = |v: i64| v.div_euclid(ONE);
    let x0 = ceil_px(a.0.min(b.0).min(c.0)).max(0);
    let x1 = floor_px(a.0.max(b.0).max(c.0)).min(camera.width as i64 - 1);
    let y0 = ceil_px(a.1.min(b.1).min(c.1)).max(0);
    let y1 = floor_px(a.1.max(b.1).max(c.1)).min(camera.height as i64 - 1);
    if x0 > x1 || y0 > y1 {
        return None;
    }
    // 1/z as a plane over the screen, from the barycentric weights (edge functions over area).
    let area_f = area as f64;
    let weight_at = |s: (i64, i64)| [edge(pb, pc, s) as f64, edge(pc, pa, s) as f64, edge(pa, pb, s) as f64];
    let plane = |w: [f64; 3]| (w[0] * a.2 + w[1] * b.2 + w[2] * c.2) / area_f;
    let origin = (x0 * ONE, y0 * ONE);
    let inv_z = plane(weight_at(origin));
    Some(ScreenTriangle {
        x: [a.0, b.0, c.0],
        y: [a.1, b.1, c.1],
        px: (x0 as u32, x1 as u32),
        py: (y0 as u32, y1 as u32),
        inv_z,
        inv_z_dx: plane(weight_at((origin.0 + ONE, origin.1))) - inv_z,
        inv_z_dy: plane(weight_at((origin.0, origin.1 + ONE))) - inv_z,
        id,
    })
}

/// Draws `triangles` in order into a `width`×`height` image.
pub fn rasterize(width: u32, height: u32, triangles: &[ScreenTriangle]) -> RasterImage {
    let (w, h) = (width as usize, height as usize);
    let bands = h.div_ceil(BAND_ROWS);
    let band_lists = bin_by_band(triangles, bands);
    let mut inv_depth = vec![0f32; w * h];
    let mut ids = vec![0u32; w * h];
    inv_depth.par_chunks_mut(BAND_ROWS * w).zip(ids.par_chunks_mut(BAND_ROWS * w)).zip(band_lists.par_iter()).enumerate().for_each(
        |(band, ((inv_depth, ids), list))| {
            let rows = (band * BAND_ROWS) as u32..((band + 1) * BAND_ROWS).min(h) as u32;
            for &t in list {
                draw(&triangles[t as usize], rows.clone(), w, inv_depth, ids);
            }
        },
    );
    let depth = inv_depth.par_iter().map(|&iz| if iz > 0.0 { 1.0 / iz } else { f32::INFINITY }).collect();
    RasterImage { width, height, depth, ids }
}

/// Triangle indices per band of rows, each list in submission order (a counting sort).
fn bin_by_band(triangles: &[ScreenTriangle], bands: usize) -> Vec<Vec<u32>> {
    let span = |t: &ScreenTriangle| t.py.0 as usize / BAND_ROWS..=t.py.1 as usize / BAND_ROWS;
    let mut counts = vec![0usize; bands];
    triangles.iter().for_each(|t| span(t).for_each(|b| counts[b] += 1));
    let mut lists: Vec<Vec<u32>> = counts.into_iter().map(Vec::with_capacity).collect();
    for (i, t) in triangles.iter().enumerate() {
        span(t).for_each(|b| lists[b].push(i as u32));
    }
    lists
}

/// Rasterizes one triangle into the rows `rows` of the image; the slices hold exactly those rows.
fn draw(t: &ScreenTriangle, rows: std::ops::Range<u32>, width: usize, inv_depth: &mut [f32], ids: &mut [u32]) {
    let (y0, y1) = (t.py.0.max(rows.start), t.py.1.min(rows.end - 1));
    if y0 > y1 {
        return;
    }
    let v = |i: usize| (t.x[i], t.y[i]);
    // Edge k is opposite vertex k. Top-left rule: a centre exactly on an edge belongs to the
    // triangle only for top edges (horizontal, interior below) and left edges (going up).
    let edges = [(v(1), v(2)), (v(2), v(0)), (v(0), v(1))];
    let start = (t.px.0 as i64 * ONE, y0 as i64 * ONE);
    let mut row_e = [0i64; 3];
    let mut step_x = [0i64; 3];
    let mut step_y = [0i64; 3];
    for (k, &(p, q)) in edges.iter().enumerate() {
        let top_left = (q.1 == p.1 && q.0 > p.0) || q.1 < p.1;
        row_e[k] = edge(p, q, start) - i64::from(!top_left);
        step_x[k] = -(q.1 - p.1) * ONE;
        step_y[k] = (q.0 - p.0) * ONE;
    }
    let row_base = rows.start as usize;
    for y in y0..=y1 {
        let mut e = row_e;
        let mut inv_z = t.inv_z + t.inv_z_dy * (y - t.py.0) as f64;
        let line = (y as usize - row_base) * width;
        for x in t.px.0..=t.px.1 {
            if (e[0] | e[1] | e[2]) >= 0 {
                let i = line + x as usize;
                let iz = inv_z as f32;
                if iz > inv_depth[i] {
                    inv_depth[i] = iz;
                    ids[i] = t.id;
                }
            }
            for k in 0..3 {
                e[k] += step_x[k];
            }
            inv_z += t.inv_z_dx;
        }
        for k in 0..3 {
            row_e[k] += step_y[k];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Mesh;

    fn camera(width: u32, height: u32) -> Camera {
        Camera::top_down(width, height, 50.0, 36.0, Vec3::new(0.0, 0.0, 1.0))
    }

    /// A flat grid of triangles in the plane z = `z` over the whole view, as the ground is.
    fn plane(cam: &Camera, z: f64, cells: usize) -> Mesh {
        let fp = cam.footprint(z).grown(0.01);
        let mut mesh = Mesh::default();
        for r in 0..=cells {
            for c in 0..=cells {
                let (fx, fy) = (c as f64 / cells as f64, r as f64 / cells as f64);
                // Jitter interior vertices so edges run at all angles.
                let j = if r % cells != 0 && c % cells != 0 { 0.3 * ((r * 7 + c * 13) % 5) as f64 / 5.0 } else { 0.0 };
                let x = fp.x0 + (fx + j / cells as f64) * (fp.x1 - fp.x0);
                mesh.positions.push(Vec3::new(x, fp.y0 + fy * (fp.y1 - fp.y0), z));
            }
        }
        let at = |r: usize, c: usize| (r * (cells + 1) + c) as u32;
        for r in 0..cells {
            for c in 0..cells {
                mesh.triangles.push([at(r, c), at(r, c + 1), at(r + 1, c + 1)]);
                mesh.triangles.push([at(r, c), at(r + 1, c + 1), at(r + 1, c)]);
            }
        }
        mesh
    }

    fn render(cam: &Camera, meshes: &[(&Mesh, u32)]) -> RasterImage {
        let mut tris = Vec::new();
        for (mesh, id) in meshes {
            project_mesh(cam, &mesh.positions, &mesh.triangles, *id, &mut tris);
        }
        rasterize(cam.width, cam.height, &tris)
    }

    #[test]
    fn shared_edges_are_watertight_and_each_pixel_drawn_once() {
        let cam = camera(97, 61);
        let mesh = plane(&cam, 0.0, 9);
        let mut tris = Vec::new();
        project_mesh(&cam, &mesh.positions, &mesh.triangles, 1, &mut tris);
        // Give every triangle its own id and count how many triangles cover each pixel when
        // the z-test cannot hide anything (coplanar, equal depth: the first one keeps it).
        let mut coverage = vec![0u32; 97 * 61];
        for t in &tris {
            let mut depth = vec![0f32; 97 * 61];
            let mut ids = vec![0u32; 97 * 61];
            let rows = 0..61;
            draw(t, rows, 97, &mut depth, &mut ids);
            ids.iter().zip(&mut coverage).for_each(|(&id, c)| *c += u32::from(id != 0));
        }
        assert!(coverage.iter().all(|&c| c == 1), "pixels drawn {:?} times", coverage.iter().filter(|&&c| c != 1).collect::<Vec<_>>());
    }

    #[test]
    fn depth_is_planar_and_nearest_surface_wins() {
        let cam = camera(64, 36);
        let far = plane(&cam, 0.0, 4);
        let near = plane(&cam, 0.25, 3);
        let image = render(&cam, &[(&far, 1), (&near, 2)]);
        assert!(image.ids.iter().all(|&id| id == 2));
        // Planar depth of a plane parallel to the image is the same everywhere, 0.75 m.
        assert!(image.depth.iter().all(|&d| (d - 0.75).abs() < 1e-6), "{:?}", &image.depth[..4]);
        let back_only = render(&cam, &[(&near, 2), (&far, 1)]);
        assert!(back_only.ids.iter().all(|&id| id == 2), "order must not matter for unequal depths");
    }

    #[test]
    fn perspective_correct_depth_on_a_slanted_triangle() {
        let cam = camera(80, 80);
        // A plane rising along x: z = 0.2 x.
        let mesh = Mesh {
            positions: vec![Vec3::new(-0.4, -0.4, -0.08), Vec3::new(0.4, -0.4, 0.08), Vec3::new(0.4, 0.4, 0.08), Vec3::new(-0.4, 0.4, -0.08)],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        };
        let image = render(&cam, &[(&mesh, 5)]);
        for v in 0..80 {
            for u in 0..80 {
                // Ray through the pixel centre hits z = 0.2 x where 1 - t = 0.2 * t * du.
                let du = (u as f64 - cam.cx) / cam.fx;
                let t = 1.0 / (1.0 + 0.2 * du);
                assert!((image.depth[v * 80 + u] as f64 - t).abs() < 2e-6, "pixel ({u},{v})");
            }
        }
    }

    #[test]
    fn back_faces_are_culled() {
        let cam = camera(32, 32);
        let mut mesh = plane(&cam, 0.0, 2);
        mesh.triangles.iter_mut().for_each(|t| t.swap(1, 2));
        assert!(render(&cam, &[(&mesh, 1)]).ids.iter().all(|&id| id == 0));
    }

    #[test]
    fn same_image_for_any_thread_count() {
        let cam = camera(200, 130);
        let far = plane(&cam, 0.0, 17);
        let tilted = Mesh { positions: far.positions.iter().map(|p| Vec3::new(p.x, p.y, 0.1 * p.x)).collect(), ..far.clone() };
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| render(&cam, &[(&far, 1), (&tilted, 2)]))
        };
        let one = run(1);
        assert_eq!(one, run(3));
        assert!(one.ids.contains(&1) && one.ids.contains(&2));
    }
}
