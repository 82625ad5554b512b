//! Coefficients to RGB: the inverse DCT of each component, chroma upsampled as libjpeg-turbo does
//! with `do_fancy_upsampling` (triangular filters for 2:1 factors, replication otherwise), its
//! fixed-point colour conversion, then Pillow's own CMYK handling (`CMYK;I` and `cmyk2rgb`).

use super::frame::{ColorSpace, Component, Frame};
use super::idct::idct_islow;
use crate::RgbImage;

/// One component's samples as stored: `width` × `height` (its downsampled size).
struct Plane {
    samples: Vec<u8>,
    width: usize,
    height: usize,
}

fn inverse_dct(c: &Component, frame: &Frame) -> Plane {
    let width = (frame.width * c.h).div_ceil(frame.max_h);
    let height = (frame.height * c.v).div_ceil(frame.max_v);
    let stride = c.width_in_blocks * 8;
    let mut full = vec![128u8; stride * c.height_in_blocks * 8];
    // A component no scan held has no table; its coefficients are all zero (mid-grey).
    let quant = c.quant.unwrap_or([0; 64]);
    for by in 0..c.height_in_blocks {
        for bx in 0..c.width_in_blocks {
            idct_islow(c.block(bx, by), &quant, &mut full[by * 8 * stride + bx * 8..], stride);
        }
    }
    let mut samples = Vec::with_capacity(width * height);
    for y in 0..height {
        samples.extend_from_slice(&full[y * stride..y * stride + width]);
    }
    Plane { samples, width, height }
}

/// The component at the frame's full resolution (`out_w` × `out_h`), upsampled by
/// (max_h / h, max_v / v) with libjpeg-turbo's method for that ratio. Neighbours past the
/// plane's edge repeat its edge, as libjpeg-turbo's context rows and edge columns do.
fn upsample(p: Plane, (fx, fy): (usize, usize), out_w: usize, out_h: usize) -> Vec<u8> {
    if (fx, fy) == (1, 1) {
        return p.samples;
    }
    let mut out = Vec::with_capacity(out_w * out_h);
    let row = |y: usize| &p.samples[y * p.width..(y + 1) * p.width];
    // The nearer and further input rows of output row y under a triangular 2:1 vertical filter.
    let rows = |y: usize| {
        let i = y / 2;
        let far = if y.is_multiple_of(2) { i.saturating_sub(1) } else { (i + 1).min(p.height - 1) };
        (row(i), row(far))
    };
    let mut line = vec![0i32; p.width];
    match (fx, fy) {
        (2, 1) if p.width > 2 => {
            for y in 0..out_h {
                line.iter_mut().zip(row(y)).for_each(|(l, &v)| *l = v as i32);
                horizontal_triangle(&line, (1, 2), 2, out_w, &mut out);
            }
        }
        (1, 2) => {
            for y in 0..out_h {
                let (near, far) = rows(y);
                let bias = if y % 2 == 0 { 1 } else { 2 };
                out.extend(
                    near.iter().zip(far).take(out_w).map(|(&n, &f)| ((3 * n as i32 + f as i32 + bias) >> 2) as u8),
                );
            }
        }
        (2, 2) if p.width > 2 => {
            for y in 0..out_h {
                let (near, far) = rows(y);
                line.iter_mut().zip(near.iter().zip(far)).for_each(|(l, (&n, &f))| *l = 3 * n as i32 + f as i32);
                horizontal_triangle(&line, (8, 7), 4, out_w, &mut out);
            }
        }
        _ => {
            for y in 0..out_h {
                let start = out.len();
                out.extend(row(y / fy).iter().flat_map(|&v| std::iter::repeat_n(v, fx)));
                out.truncate(start + out_w);
            }
        }
    }
    out
}

/// libjpeg-turbo's horizontal 2:1 triangle over one row of `line` (samples, or column sums
/// already weighted 3:1): (3 · nearer + further + bias) >> shift, with the even outputs' bias
/// `biases.0` and the odd ones' `biases.1`. Its special edge cases are this formula with the
/// edge input repeated.
fn horizontal_triangle(line: &[i32], biases: (i32, i32), shift: u32, out_w: usize, out: &mut Vec<u8>) {
    let last = line.len() - 1;
    for x in 0..out_w {
        let i = x / 2;
        let v = if x % 2 == 0 {
            (3 * line[i] + line[i.saturating_sub(1)] + biases.0) >> shift
        } else {
            (3 * line[i] + line[(i + 1).min(last)] + biases.1) >> shift
        };
        out.push(v as u8);
    }
}

/// libjpeg-turbo's YCbCr → RGB tables (16-bit fixed point, `build_ycc_rgb_table`).
struct YccTables {
    cr_r: [i32; 256],
    cb_b: [i32; 256],
    cr_g: [i64; 256],
    cb_g: [i64; 256],
}

impl YccTables {
    fn new() -> Self {
        const ONE_HALF: i64 = 1 << 15;
        let fix = |x: f64| (x * 65536.0 + 0.5) as i64;
        let mut t = YccTables { cr_r: [0; 256], cb_b: [0; 256], cr_g: [0; 256], cb_g: [0; 256] };
        for i in 0..256 {
            let x = i as i64 - 128;
            t.cr_r[i] = ((fix(1.40200) * x + ONE_HALF) >> 16) as i32;
            t.cb_b[i] = ((fix(1.77200) * x + ONE_HALF) >> 16) as i32;
            t.cr_g[i] = -fix(0.71414) * x;
            t.cb_g[i] = -fix(0.34414) * x + ONE_HALF;
        }
        t
    }

    fn rgb(&self, y: u8, cb: u8, cr: u8) -> [u8; 3] {
        let y = y as i32;
        let (cb, cr) = (cb as usize, cr as usize);
        let clamp = |v: i32| v.clamp(0, 255) as u8;
        [clamp(y + self.cr_r[cr]), clamp(y + ((self.cb_g[cb] + self.cr_g[cr]) >> 16) as i32), clamp(y + self.cb_b[cb])]
    }
}

/// Pillow's `cmyk2rgb` on the inverted (Adobe) samples libjpeg-turbo returns.
fn cmyk_to_rgb(c: u8, m: u8, y: u8, k: u8) -> [u8; 3] {
    let nk = k as i32; // 255 - (255 - k)
    let muldiv255 = |a: i32, b: i32| {
        let t = a * b + 128;
        ((t >> 8) + t) >> 8
    };
    let channel = |v: u8| (nk - muldiv255(255 - v as i32, nk)).clamp(0, 255) as u8;
    [channel(c), channel(m), channel(y)]
}

pub(super) fn to_rgb(frame: &Frame) -> Result<RgbImage, String> {
    let (w, h) = (frame.width, frame.height);
    let mut planes = Vec::with_capacity(frame.components.len());
    for c in &frame.components {
        if !frame.max_h.is_multiple_of(c.h) || !frame.max_v.is_multiple_of(c.v) {
            return Err("JPEG with fractional sampling factors (libjpeg-turbo refuses them too)".into());
        }
        planes.push(upsample(inverse_dct(c, frame), (frame.max_h / c.h, frame.max_v / c.v), w, h));
    }
    let mut pixels = vec![0u8; w * h * 3];
    let px = pixels.chunks_exact_mut(3);
    let t = YccTables::new();
    match (frame.color, &planes[..]) {
        (ColorSpace::Grey, [g]) => px.zip(g).for_each(|(p, &g)| p.fill(g)),
        (ColorSpace::Rgb, [r, g, b]) => {
            px.zip(r.iter().zip(g).zip(b)).for_each(|(p, ((&r, &g), &b))| p.copy_from_slice(&[r, g, b]))
        }
        (ColorSpace::YCbCr, [y, cb, cr]) => {
            px.zip(y.iter().zip(cb).zip(cr)).for_each(|(p, ((&y, &cb), &cr))| p.copy_from_slice(&t.rgb(y, cb, cr)))
        }
        (ColorSpace::Cmyk, [c, m, y, k]) => px
            .zip(c.iter().zip(m).zip(y).zip(k))
            .for_each(|(p, (((&c, &m), &y), &k))| p.copy_from_slice(&cmyk_to_rgb(c, m, y, k))),
        // libjpeg-turbo's `ycck_cmyk_convert`: C, M, Y = 255 − R, G, B of the YCbCr triple.
        (ColorSpace::Ycck, [y, cb, cr, k]) => {
            px.zip(y.iter().zip(cb).zip(cr).zip(k)).for_each(|(p, (((&y, &cb), &cr), &k))| {
                let [r, g, b] = t.rgb(y, cb, cr);
                p.copy_from_slice(&cmyk_to_rgb(255 - r, 255 - g, 255 - b, k));
            })
        }
        _ => unreachable!("the colour space follows the component count"),
    }
    Ok(RgbImage { width: w, height: h, pixels })
}
