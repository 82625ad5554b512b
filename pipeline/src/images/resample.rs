//! Separable antialiased resizing of 8-bit RGB, bit-exact with two references that share one
//! design (Pillow's Resample.c, which ATen's uint8 kernel adapts) but differ in details:
//! - [`resize_pil`]: `PIL.Image.resize` (diffusers' control images): weights in 22-bit fixed point.
//! - [`resize_torch`]: `torch.nn.functional.interpolate(uint8, antialias=True)` on CPU (what
//!   transformers' torchvision-backed CLIP processor runs): weights in int16 with a precision
//!   chosen per axis from the largest weight, and Keys' cubic written in another order.
//!
//! Both: two passes with an 8-bit intermediate, horizontal first (Pillow goes vertical first
//! when that shrinks much more); an axis whose size does not change is not touched; each output
//! value is `(Σ k·p + half) >> precision`, clamped.

use crate::RgbImage;

/// Resampling filter (PIL's names).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Filter {
    Bilinear,
    /// Keys' cubic with a = -0.5.
    Bicubic,
    /// Three-lobed Lanczos (Pillow only).
    Lanczos,
}

impl Filter {
    fn support(self) -> f64 {
        match self {
            Filter::Bilinear => 1.0,
            Filter::Bicubic => 2.0,
            Filter::Lanczos => 3.0,
        }
    }
}

fn bilinear(x: f64) -> f64 {
    let x = x.abs();
    if x < 1.0 {
        1.0 - x
    } else {
        0.0
    }
}

/// Pillow's expression order; the double results differ from ATen's in the last bits.
fn bicubic_pil(x: f64) -> f64 {
    const A: f64 = -0.5;
    let x = x.abs();
    if x < 1.0 {
        ((A + 2.0) * x - (A + 3.0)) * x * x + 1.0
    } else if x < 2.0 {
        (((x - 5.0) * x + 8.0) * x - 4.0) * A
    } else {
        0.0
    }
}

fn bicubic_torch(x: f64) -> f64 {
    const A: f64 = -0.5;
    let x = x.abs();
    if x < 1.0 {
        ((A + 2.0) * x - (A + 3.0)) * x * x + 1.0
    } else if x < 2.0 {
        ((A * x - 5.0 * A) * x + 8.0 * A) * x - 4.0 * A
    } else {
        0.0
    }
}

fn sinc(x: f64) -> f64 {
    if x == 0.0 {
        return 1.0;
    }
    let x = x * std::f64::consts::PI;
    x.sin() / x
}

fn lanczos(x: f64) -> f64 {
    if (-3.0..3.0).contains(&x) {
        sinc(x) * sinc(x / 3.0)
    } else {
        0.0
    }
}

/// Per output sample: first input index, tap count, and `ksize` normalised double weights.
struct Taps {
    ksize: usize,
    bounds: Vec<(usize, usize)>,
    weights: Vec<f64>,
}

fn taps(in_size: usize, out_size: usize, support: f64, filter: fn(f64) -> f64) -> Taps {
    let scale = in_size as f64 / out_size as f64;
    let filterscale = scale.max(1.0);
    let support = support * filterscale;
    let ksize = support.ceil() as usize * 2 + 1;
    let ss = 1.0 / filterscale;
    let mut bounds = Vec::with_capacity(out_size);
    let mut weights = vec![0.0; out_size * ksize];
    for xx in 0..out_size {
        let center = (xx as f64 + 0.5) * scale;
        // Truncation toward zero, as C's (int) cast.
        let xmin = ((center - support + 0.5) as i64).max(0) as usize;
        let xmax = ((center + support + 0.5) as i64).min(in_size as i64) as usize;
        let n = xmax.saturating_sub(xmin).min(ksize);
        let k = &mut weights[xx * ksize..xx * ksize + n];
        let mut total = 0.0;
        for (x, w) in k.iter_mut().enumerate() {
            *w = filter(((x + xmin) as f64 - center + 0.5) * ss);
            total += *w;
        }
        if total != 0.0 {
            k.iter_mut().for_each(|w| *w /= total);
        }
        bounds.push((xmin, n));
    }
    Taps { ksize, bounds, weights }
}

/// Round half away from zero, as `(int)(v ± 0.5)`.
fn fixed(w: f64, precision: u32) -> i32 {
    let v = w * (1u32 << precision) as f64;
    if v < 0.0 {
        (v - 0.5) as i32
    } else {
        (v + 0.5) as i32
    }
}

struct Kernel {
    taps: Taps,
    fixed: Vec<i32>,
    precision: u32,
}

fn pil_kernel(in_size: usize, out_size: usize, filter: Filter) -> Kernel {
    let f = match filter {
        Filter::Bilinear => bilinear,
        Filter::Bicubic => bicubic_pil,
        Filter::Lanczos => lanczos,
    };
    let taps = taps(in_size, out_size, filter.support(), f);
    const PRECISION_BITS: u32 = 32 - 8 - 2;
    let fixed = taps.weights.iter().map(|&w| fixed(w, PRECISION_BITS)).collect();
    Kernel { taps, fixed, precision: PRECISION_BITS }
}

fn torch_kernel(in_size: usize, out_size: usize, filter: Filter) -> Kernel {
    let f = match filter {
        Filter::Bilinear => bilinear,
        Filter::Bicubic => bicubic_torch,
        Filter::Lanczos => unreachable!("checked by resize_torch"),
    };
    let taps = taps(in_size, out_size, filter.support(), f);
    let max = taps.weights.iter().cloned().fold(0.0, f64::max);
    // The most bits that keep the largest weight, rounded, below 2^15 (an int16).
    let mut precision = 0;
    while precision < 22 {
        if (0.5 + max * (1u32 << (precision + 1)) as f64) as i32 >= 1 << 15 {
            break;
        }
        precision += 1;
    }
    let fixed = taps.weights.iter().map(|&w| fixed(w, precision) as i16 as i32).collect();
    Kernel { taps, fixed, precision }
}

fn convolve(values: impl Iterator<Item = u8>, k: &[i32], precision: u32) -> u8 {
    let sum = values.zip(k).fold(1i64 << (precision - 1), |s, (p, &w)| s + p as i64 * w as i64);
    (sum >> precision).clamp(0, 255) as u8
}

fn horizontal(src: &[u8], width: usize, height: usize, kernel: &Kernel) -> Vec<u8> {
    let out_w = kernel.taps.bounds.len();
    let mut out = Vec::with_capacity(out_w * height * 3);
    for row in src.chunks_exact(width * 3).take(height) {
        for (xx, &(xmin, n)) in kernel.taps.bounds.iter().enumerate() {
            let k = &kernel.fixed[xx * kernel.taps.ksize..xx * kernel.taps.ksize + n];
            for c in 0..3 {
                out.push(convolve((xmin..xmin + n).map(|x| row[x * 3 + c]), k, kernel.precision));
            }
        }
    }
    out
}

fn vertical(src: &[u8], width: usize, kernel: &Kernel) -> Vec<u8> {
    let stride = width * 3;
    let mut out = Vec::with_capacity(stride * kernel.taps.bounds.len());
    for (yy, &(ymin, n)) in kernel.taps.bounds.iter().enumerate() {
        let k = &kernel.fixed[yy * kernel.taps.ksize..yy * kernel.taps.ksize + n];
        for i in 0..stride {
            out.push(convolve((ymin..ymin + n).map(|y| src[y * stride + i]), k, kernel.precision));
        }
    }
    out
}

fn resize_with(
    image: &RgbImage,
    width: usize,
    height: usize,
    kernel: fn(usize, usize, Filter) -> Kernel,
    filter: Filter,
    vertical_first: bool,
) -> RgbImage {
    assert!(width > 0 && height > 0 && image.width > 0 && image.height > 0, "resize of an empty image");
    assert_eq!(image.pixels.len(), image.width * image.height * 3, "RGB image data does not match its size");
    let mut pixels = image.pixels.clone();
    if vertical_first {
        if height != image.height {
            pixels = vertical(&pixels, image.width, &kernel(image.height, height, filter));
        }
        if width != image.width {
            pixels = horizontal(&pixels, image.width, height, &kernel(image.width, width, filter));
        }
        return RgbImage { width, height, pixels };
    }
    if width != image.width {
        pixels = horizontal(&pixels, image.width, image.height, &kernel(image.width, width, filter));
    }
    if height != image.height {
        pixels = vertical(&pixels, width, &kernel(image.height, height, filter));
    }
    RgbImage { width, height, pixels }
}

/// `image.resize((width, height), resample=filter)` of Pillow, for an RGB image.
pub fn resize_pil(image: &RgbImage, width: usize, height: usize, filter: Filter) -> RgbImage {
    // Pillow 13 (Resample.c) runs the vertical pass first when the vertical shrink is more than
    // twice the horizontal one.
    let (dh, dw) = (image.height as i64 - height as i64, image.width as i64 - width as i64);
    resize_with(image, width, height, pil_kernel, filter, dh > 0 && dh > dw * 2)
}

/// `interpolate(x, (height, width), mode, antialias=True)` of ATen on a uint8 CPU tensor (the
/// native uint8 path; torchvision takes it for bicubic, and for bilinear on AVX2/NEON CPUs).
/// Lanczos has no ATen kernel: panics.
pub fn resize_torch(image: &RgbImage, width: usize, height: usize, filter: Filter) -> RgbImage {
    assert!(filter != Filter::Lanczos, "ATen has no antialiased Lanczos kernel");
    resize_with(image, width, height, torch_kernel, filter, false)
}
