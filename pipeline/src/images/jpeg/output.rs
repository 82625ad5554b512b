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

impl Plane {
    fn at(&self, x: usize, y: usize) -> i32 {
        self.samples[y * self.width + x] as i32
    }
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
    let samples = (0..height).flat_map(|y| full[y * stride..y * stride + width].iter().copied()).collect();
    Plane { samples, width, height }
}

/// The component at the frame's full resolution (`out_w` × `out_h`), upsampled by
/// (max_h / h, max_v / v) with libjpeg-turbo's method for that ratio. Neighbours past the
/// plane's edge repeat its edge, as libjpeg-turbo's context rows and edge columns do.
fn upsample(p: &Plane, (fx, fy): (usize, usize), out_w: usize, out_h: usize) -> Vec<u8> {
    let mut out = Vec::with_capacity(out_w * out_h);
    let row_near = |y: usize| y / fy;
    // The vertically nearer and further rows of output row y (triangular 2:1 filters).
    let rows = |y: usize| {
        let i = y / 2;
        let far = if y % 2 == 0 { i.saturating_sub(1) } else { (i + 1).min(p.height - 1) };
        (i, far)
    };
    match (fx, fy) {
        (2, 1) if p.width > 2 => {
            for y in 0..out_h {
                for x in 0..out_w {
                    let (i, s) = (x / 2, y);
                    let v = if x % 2 == 0 {
                        if i == 0 { p.at(0, s) } else { (3 * p.at(i, s) + p.at(i - 1, s) + 1) >> 2 }
                    } else if i == p.width - 1 {
                        p.at(i, s)
                    } else {
                        (3 * p.at(i, s) + p.at(i + 1, s) + 2) >> 2
                    };
                    out.push(v as u8);
                }
            }
        }
        (1, 2) => {
            for y in 0..out_h {
                let (near, far) = rows(y);
                let bias = if y % 2 == 0 { 1 } else { 2 };
                out.extend((0..out_w).map(|x| ((3 * p.at(x, near) + p.at(x, far) + bias) >> 2) as u8));
            }
        }
        (2, 2) if p.width > 2 => {
            for y in 0..out_h {
                let (near, far) = rows(y);
                let colsum = |i: usize| 3 * p.at(i, near) + p.at(i, far);
                for x in 0..out_w {
                    let i = x / 2;
                    let v = if x % 2 == 0 {
                        if i == 0 { (colsum(0) * 4 + 8) >> 4 } else { (colsum(i) * 3 + colsum(i - 1) + 8) >> 4 }
                    } else if i == p.width - 1 {
                        (colsum(i) * 4 + 7) >> 4
                    } else {
                        (colsum(i) * 3 + colsum(i + 1) + 7) >> 4
                    };
                    out.push(v as u8);
                }
            }
        }
        _ => {
            for y in 0..out_h {
                out.extend((0..out_w).map(|x| p.at(x / fx, row_near(y)) as u8));
            }
        }
    }
    out
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
        if frame.max_h % c.h != 0 || frame.max_v % c.v != 0 {
            return Err("JPEG with fractional sampling factors (libjpeg-turbo refuses them too)".into());
        }
        planes.push(upsample(&inverse_dct(c, frame), (frame.max_h / c.h, frame.max_v / c.v), w, h));
    }
    let mut pixels = Vec::with_capacity(w * h * 3);
    match frame.color {
        ColorSpace::Grey => pixels.extend(planes[0].iter().flat_map(|&g| [g; 3])),
        ColorSpace::Rgb => pixels.extend((0..w * h).flat_map(|i| [planes[0][i], planes[1][i], planes[2][i]])),
        ColorSpace::YCbCr => {
            let t = YccTables::new();
            pixels.extend((0..w * h).flat_map(|i| t.rgb(planes[0][i], planes[1][i], planes[2][i])));
        }
        ColorSpace::Cmyk => pixels.extend((0..w * h).flat_map(|i| cmyk_to_rgb(planes[0][i], planes[1][i], planes[2][i], planes[3][i]))),
        ColorSpace::Ycck => {
            // libjpeg-turbo's `ycck_cmyk_convert`: C, M, Y = 255 − R, G, B of the YCbCr triple.
            let t = YccTables::new();
            pixels.extend((0..w * h).flat_map(|i| {
                let [r, g, b] = t.rgb(planes[0][i], planes[1][i], planes[2][i]);
                cmyk_to_rgb(255 - r, 255 - g, 255 - b, planes[3][i])
            }));
        }
    }
    Ok(RgbImage { width: w, height: h, pixels })
}
