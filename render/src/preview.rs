//! preview.png, for people: the depth map lit from the upper left (normals from depth), the
//! compost brown and the mushrooms white, each instance tinted with its own colour and outlined
//! where it borders another id.

use rayon::prelude::*;

use crate::frame::Frame;

const COMPOST: [f64; 3] = [92.0, 72.0, 54.0];
const MUSHROOM: [f64; 3] = [238.0, 234.0, 224.0];
const TINT: f64 = 0.25;

pub fn preview_image(frame: &Frame) -> Vec<u8> {
    draw(frame, true)
}

/// The scene as an img2img start: compost brown and mushrooms white, lit from the depth, with
/// no tints or outlines.
pub fn shaded_image(frame: &Frame) -> Vec<u8> {
    draw(frame, false)
}

/// With `mark_instances`, each instance tinted with its colour and outlined.
fn draw(frame: &Frame, mark_instances: bool) -> Vec<u8> {
    let (w, h) = (frame.width(), frame.height());
    let light = normalize([-0.45, -0.55, -1.0]); // towards the light, camera axes (z forward)
    let tints: Vec<[f64; 3]> = (0..=frame.instances.len()).map(|id| instance_colour(id as u16)).collect();
    let (fx, fy) = frame.focal();
    let mut rgb = vec![0u8; w * h * 3];
    rgb.par_chunks_mut(w * 3).enumerate().for_each(|(y, row)| {
        for x in 0..w {
            let i = y * w + x;
            let z = frame.depth[i] as f64;
            if !z.is_finite() {
                continue;
            }
            let at = |dx: isize, dy: isize| {
                let (xx, yy) = (
                    (x as isize + dx).clamp(0, w as isize - 1) as usize,
                    (y as isize + dy).clamp(0, h as isize - 1) as usize,
                );
                let d = frame.depth[yy * w + xx] as f64;
                if d.is_finite() {
                    d
                } else {
                    z
                }
            };
            // Depth slope per metre across the image plane; a pixel spans z / f metres there.
            let (sx, sy) = (fx / z, fy / z);
            let gx = (at(1, 0) - at(-1, 0)) / 2.0 * sx;
            let gy = (at(0, 1) - at(0, -1)) / 2.0 * sy;
            let normal = normalize([gx, gy, -1.0]);
            let lambert = (normal[0] * light[0] + normal[1] * light[1] + normal[2] * light[2]).max(0.0);
            let shade = 0.25 + 0.75 * lambert;
            let id = frame.ids[i];
            let mut colour = if id == 0 { COMPOST } else { MUSHROOM }.map(|c| c * shade);
            if id != 0 && mark_instances {
                let tint = tints[id as usize];
                let edge = [(1, 0), (-1, 0), (0, 1), (0, -1)].iter().any(|&(dx, dy)| {
                    let (xx, yy) = (x as isize + dx, y as isize + dy);
                    xx >= 0
                        && yy >= 0
                        && (xx as usize) < w
                        && (yy as usize) < h
                        && frame.ids[yy as usize * w + xx as usize] != id
                });
                let alpha = if edge { 0.9 } else { TINT };
                colour =
                    [0, 1, 2].map(|c| colour[c] * (1.0 - alpha) + tint[c] * alpha * if edge { 1.0 } else { shade });
            }
            // + 0.5 and a saturating cast: rounding without the libm call.
            row[x * 3..x * 3 + 3].copy_from_slice(&colour.map(|c| (c + 0.5) as u8));
        }
    });
    rgb
}

fn normalize(v: [f64; 3]) -> [f64; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|c| c / n)
}

/// Well-separated hues for consecutive ids (golden-ratio steps round the colour wheel).
fn instance_colour(id: u16) -> [f64; 3] {
    let hue = (id as f64 * 0.618_033_988_75).fract() * 6.0;
    let (s, v) = (0.7, 255.0);
    let f = hue.fract();
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f)));
    match hue as u32 {
        0 => [v, t, p],
        1 => [q, v, p],
        2 => [p, v, t],
        3 => [p, q, v],
        4 => [t, p, v],
        _ => [v, p, q],
    }
}
