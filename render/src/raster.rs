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

/// A front-facing triangle in screen space, clockwise on the y-down screen (48 bytes: a frame
/// holds a few hundred thousand).
#[derive(Clone, Copy, Debug)]
pub struct ScreenTriangle {
    /// Fixed-point vertex coordinates (|coordinate| < 2^28, see `project_vertices`).
    x: [i32; 3],
    y: [i32; 3],
    /// Inclusive pixel bounds, clipped to the image.
    px: (u16, u16),
    py: (u16, u16),
    /// 1/z at pixel (px.0, py.0) and its steps per pixel in x and y. In f32, 1/z ≈ 1 carries
    /// about 1e-7 relative error, a tenth of a micrometre of depth at 1 m.
    inv_z: f32,
    inv_z_dx: f32,
    inv_z_dy: f32,
    id: u16,
}

/// Depth (metres, +∞ where nothing was drawn) and id (0 where nothing was drawn) per pixel,
/// row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct RasterImage {
    pub width: u32,
    pub height: u32,
    pub depth: Vec<f32>,
    pub ids: Vec<u16>,
}

/// Triangles per list when a large mesh (the ground) is set up in parallel.
const CHUNK: usize = 8192;

/// Projects a world-space mesh and sets up its visible triangles, tagged with `id`: lists of
/// triangles whose concatenation keeps the order of `triangles`.
pub fn project_mesh(camera: &Camera, positions: &[Vec3], triangles: &[[u32; 3]], id: u16) -> Vec<Vec<ScreenTriangle>> {
    let vertices = project_vertices(camera, positions);
    let setup_all = |tris: &[[u32; 3]]| -> Vec<ScreenTriangle> {
        tris.iter()
            .filter_map(|tri| {
                let [Some(a), Some(b), Some(c)] = tri.map(|i| vertices[i as usize]) else { return None };
                // Counter-clockwise in the world is counter-clockwise on screen, i.e. negative
                // doubled area in y-down coordinates; swapping two vertices makes it positive.
                setup(camera, a, c, b, id)
            })
            .collect()
    };
    if triangles.len() > CHUNK {
        triangles.par_chunks(CHUNK).map(setup_all).collect()
    } else {
        vec![setup_all(triangles)]
    }
}

/// Fixed-point screen position and 1/z of a vertex.
#[derive(Clone, Copy, Debug)]
struct Vertex {
    x: i64,
    y: i64,
    inv_z: f64,
}

/// Vertices behind the near plane or far outside any image (2^20 px) become None, which keeps
/// fixed-point values below 2^28 and edge products inside i64.
fn project_vertices(camera: &Camera, positions: &[Vec3]) -> Vec<Option<Vertex>> {
    let project = |&p: &Vec3| {
        let (u, v, z) = camera.project(p);
        let bound = (1 << 20) as f64;
        (z > NEAR_M && u.abs() < bound && v.abs() < bound).then(|| Vertex {
            x: round_to_i64(u * ONE as f64),
            y: round_to_i64(v * ONE as f64),
            inv_z: 1.0 / z,
        })
    };
    if positions.len() > CHUNK {
        positions.par_iter().map(project).collect()
    } else {
        positions.iter().map(project).collect()
    }
}

/// Rounds half away from zero, like `f64::round`, without the libm call that baseline x86-64
/// makes of it.
fn round_to_i64(v: f64) -> i64 {
    (v + 0.5f64.copysign(v)) as i64
}

/// Doubled signed area of the edge p→q against point s; positive on the inside of a clockwise
/// (y-down) triangle.
fn edge(p: (i64, i64), q: (i64, i64), s: (i64, i64)) -> i64 {
    (q.0 - p.0) * (s.1 - p.1) - (q.1 - p.1) * (s.0 - p.0)
}

fn setup(camera: &Camera, a: Vertex, b: Vertex, c: Vertex, id: u16) -> Option<ScreenTriangle> {
    let area = edge((a.x, a.y), (b.x, b.y), (c.x, c.y));
    if area <= 0 {
        return None; // back-facing or degenerate
    }
    let ceil_px = |v: i64| (v + ONE - 1).div_euclid(ONE);
    let floor_px = |v: i64| v.div_euclid(ONE);
    let x0 = ceil_px(a.x.min(b.x).min(c.x)).max(0);
    let x1 = floor_px(a.x.max(b.x).max(c.x)).min(camera.width as i64 - 1);
    let y0 = ceil_px(a.y.min(b.y).min(c.y)).max(0);
    let y1 = floor_px(a.y.max(b.y).max(c.y)).min(camera.height as i64 - 1);
    if x0 > x1 || y0 > y1 {
        return None;
    }
    // 1/z is the barycentric blend of the vertices' 1/z; the weights are the edge functions
    // over the area, so its gradient follows from the edges' slopes.
    let scale = ONE as f64 / area as f64;
    let dx = -((c.y - b.y) as f64 * a.inv_z + (a.y - c.y) as f64 * b.inv_z + (b.y - a.y) as f64 * c.inv_z) * scale;
    let dy = ((c.x - b.x) as f64 * a.inv_z + (a.x - c.x) as f64 * b.inv_z + (b.x - a.x) as f64 * c.inv_z) * scale;
    let (ox, oy) = (x0 as f64 - a.x as f64 / ONE as f64, y0 as f64 - a.y as f64 / ONE as f64);
    Some(ScreenTriangle {
        x: [a.x as i32, b.x as i32, c.x as i32],
        y: [a.y as i32, b.y as i32, c.y as i32],
        px: (x0 as u16, x1 as u16),
        py: (y0 as u16, y1 as u16),
        inv_z: (a.inv_z + dx * ox + dy * oy) as f32,
        inv_z_dx: dx as f32,
        inv_z_dy: dy as f32,
        id,
    })
}

/// Draws the triangles of `lists`, list by list and in order within each, into a
/// `width`×`height` image (at most `MAX_SIDE` pixels a side).
pub fn rasterize(width: u32, height: u32, lists: &[Vec<ScreenTriangle>]) -> RasterImage {
    let (w, h) = (width as usize, height as usize);
    let bands = h.div_ceil(BAND_ROWS);
    let bins = bin_by_band(lists, bands);
    // The buffer holds 1/z while drawing and becomes z in place afterwards.
    let mut depth = vec![0f32; w * h];
    let mut ids = vec![0u16; w * h];
    depth.par_chunks_mut(BAND_ROWS * w).zip(ids.par_chunks_mut(BAND_ROWS * w)).enumerate().for_each(
        |(band, (inv_depth, ids))| {
            let rows = (band * BAND_ROWS) as u32..((band + 1) * BAND_ROWS).min(h) as u32;
            for (list, list_bins) in lists.iter().zip(&bins) {
                for &t in &list_bins[band] {
                    draw(&list[t as usize], rows.clone(), w, inv_depth, ids);
                }
            }
            inv_depth.iter_mut().for_each(|v| *v = if *v > 0.0 { 1.0 / *v } else { f32::INFINITY });
        },
    );
    RasterImage { width, height, depth, ids }
}

/// For each list, the indices of its triangles that reach each band of rows, in order; lists
/// are binned in parallel.
fn bin_by_band(lists: &[Vec<ScreenTriangle>], bands: usize) -> Vec<Vec<Vec<u32>>> {
    lists
        .par_iter()
        .map(|list| {
            let mut bins = vec![Vec::new(); bands];
            for (i, t) in list.iter().enumerate() {
                let span = t.py.0 as usize / BAND_ROWS..=t.py.1 as usize / BAND_ROWS;
                bins[span].iter_mut().for_each(|bin| bin.push(i as u32));
            }
            bins
        })
        .collect()
}

/// Rasterizes one triangle into the rows `rows` of the image; the slices hold exactly those rows.
fn draw(t: &ScreenTriangle, rows: std::ops::Range<u32>, width: usize, inv_depth: &mut [f32], ids: &mut [u16]) {
    let (y0, y1) = ((t.py.0 as u32).max(rows.start), (t.py.1 as u32).min(rows.end - 1));
    if y0 > y1 {
        return;
    }
    let v = |i: usize| (t.x[i] as i64, t.y[i] as i64);
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
        // Evaluated afresh at each pixel rather than accumulated, so f32 rounding never builds
        // up along a row.
        let row_inv_z = t.inv_z + t.inv_z_dy * (y - t.py.0 as u32) as f32;
        let line = (y as usize - row_base) * width;
        for x in t.px.0..=t.px.1 {
            if (e[0] | e[1] | e[2]) >= 0 {
                let i = line + x as usize;
                let inv_z = row_inv_z + t.inv_z_dx * (x - t.px.0) as f32;
                if inv_z > inv_depth[i] {
                    inv_depth[i] = inv_z;
                    ids[i] = t.id;
                }
            }
            for k in 0..3 {
                e[k] += step_x[k];
            }
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

    fn render(cam: &Camera, meshes: &[(&Mesh, u16)]) -> RasterImage {
        let lists: Vec<Vec<ScreenTriangle>> =
            meshes.iter().flat_map(|(mesh, id)| project_mesh(cam, &mesh.positions, &mesh.triangles, *id)).collect();
        rasterize(cam.width, cam.height, &lists)
    }

    #[test]
    fn shared_edges_are_watertight_and_each_pixel_drawn_once() {
        let cam = camera(97, 61);
        let mesh = plane(&cam, 0.0, 9);
        let tris: Vec<ScreenTriangle> = project_mesh(&cam, &mesh.positions, &mesh.triangles, 1).concat();
        // Give every triangle its own id and count how many triangles cover each pixel when
        // the z-test cannot hide anything (coplanar, equal depth: the first one keeps it).
        let mut coverage = vec![0u32; 97 * 61];
        for t in &tris {
            let mut depth = vec![0f32; 97 * 61];
            let mut ids = vec![0u16; 97 * 61];
            let rows = 0..61;
            draw(t, rows, 97, &mut depth, &mut ids);
            ids.iter().zip(&mut coverage).for_each(|(&id, c)| *c += u32::from(id != 0));
        }
        assert!(
            coverage.iter().all(|&c| c == 1),
            "pixels drawn {:?} times",
            coverage.iter().filter(|&&c| c != 1).collect::<Vec<_>>()
        );
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
            positions: vec![
                Vec3::new(-0.4, -0.4, -0.08),
                Vec3::new(0.4, -0.4, 0.08),
                Vec3::new(0.4, 0.4, 0.08),
                Vec3::new(-0.4, 0.4, -0.08),
            ],
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
        let tilted =
            Mesh { positions: far.positions.iter().map(|p| Vec3::new(p.x, p.y, 0.1 * p.x)).collect(), ..far.clone() };
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| render(&cam, &[(&far, 1), (&tilted, 2)]))
        };
        let one = run(1);
        assert_eq!(one, run(3));
        assert!(one.ids.contains(&1) && one.ids.contains(&2));
    }
}
