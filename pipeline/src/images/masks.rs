//! Masks at the image's resolution made ready for the latent grid: feathered (a separable
//! Gaussian of standard deviation PX/2 over taps −PX..PX, edges clamped, horizontal then
//! vertical) and resized as PyTorch's bilinear `interpolate` resizes (align_corners false),
//! which is how ComfyUI brings a conditioning or noise mask to the latent's size. In f64, so a
//! strength compared with a step's threshold falls on the same side in any reimplementation.

/// `mask` (`width` × `height`, row-major) blurred over `px` pixels; 0 leaves it as it is.
pub fn feather(mask: &[f64], width: usize, height: usize, px: usize) -> Vec<f64> {
    if px == 0 {
        return mask.to_vec();
    }
    let sigma = px as f64 / 2.0;
    let offsets: Vec<isize> = (-(px as isize)..=px as isize).collect();
    let raw: Vec<f64> = offsets.iter().map(|&k| (-((k * k) as f64) / (2.0 * sigma * sigma)).exp()).collect();
    let sum: f64 = raw.iter().sum();
    let taps: Vec<f64> = raw.iter().map(|t| t / sum).collect();
    let clamp = |i: isize, n: usize| i.clamp(0, n as isize - 1) as usize;
    let mut across = vec![0.0; mask.len()];
    for (tap, &k) in taps.iter().zip(&offsets) {
        for y in 0..height {
            for x in 0..width {
                across[y * width + x] += tap * mask[y * width + clamp(x as isize + k, width)];
            }
        }
    }
    let mut out = vec![0.0; mask.len()];
    for (tap, &k) in taps.iter().zip(&offsets) {
        for y in 0..height {
            let from = clamp(y as isize + k, height) * width;
            for x in 0..width {
                out[y * width + x] += tap * across[from + x];
            }
        }
    }
    out
}

/// `mask` resized from `width` × `height` to `out_width` × `out_height`, bilinear, half-pixel
/// centres, source coordinates clamped at 0 (PyTorch's `interpolate(mode="bilinear")`).
pub fn bilinear(mask: &[f64], width: usize, height: usize, out_width: usize, out_height: usize) -> Vec<f64> {
    let axis = |n_in: usize, n_out: usize| -> Vec<(usize, usize, f64)> {
        (0..n_out)
            .map(|d| {
                let src = ((d as f64 + 0.5) * (n_in as f64 / n_out as f64) - 0.5).max(0.0);
                let lo = src.floor() as usize;
                (lo, (lo + 1).min(n_in - 1), src - lo as f64)
            })
            .collect()
    };
    let (rows, cols) = (axis(height, out_height), axis(width, out_width));
    let mut out = Vec::with_capacity(out_width * out_height);
    for &(y0, y1, fy) in &rows {
        for &(x0, x1, fx) in &cols {
            let at = |y: usize, x: usize| mask[y * width + x];
            let top = at(y0, x0) * (1.0 - fx) + at(y0, x1) * fx;
            let bottom = at(y1, x0) * (1.0 - fx) + at(y1, x1) * fx;
            out.push(top * (1.0 - fy) + bottom * fy);
        }
    }
    out
}

/// `mask` feathered by `px`, then on a `latent` (width, height) grid.
pub fn latent_mask(mask: &[f64], width: usize, height: usize, px: usize, latent: (usize, usize)) -> Vec<f64> {
    bilinear(&feather(mask, width, height, px), width, height, latent.0, latent.1)
}

/// The masks of a prompt per category over an image whose pixels have `categories` (0 the
/// background): first the scene prompt's, over every pixel of no `prompted` category, then each
/// prompted category's own; feathered by `px` and on the `latent` grid.
pub fn region_masks(
    categories: &[u32],
    width: usize,
    height: usize,
    prompted: &[u32],
    px: usize,
    latent: (usize, usize),
) -> Vec<Vec<f32>> {
    let own: Vec<Vec<f64>> =
        prompted.iter().map(|&k| categories.iter().map(|&c| f64::from(u8::from(c == k))).collect()).collect();
    let rest: Vec<f64> = (0..categories.len()).map(|p| 1.0 - own.iter().map(|m| m[p]).sum::<f64>()).collect();
    std::iter::once(&rest)
        .chain(&own)
        .map(|m| latent_mask(m, width, height, px, latent).into_iter().map(|v| v as f32).collect())
        .collect()
}

/// Each pixel's strength (`strengths`) over `largest`, feathered by `px`, on the `latent` grid.
pub fn relative_strengths(
    strengths: &[f64],
    width: usize,
    height: usize,
    largest: f64,
    px: usize,
    latent: (usize, usize),
) -> Vec<f64> {
    latent_mask(strengths, width, height, px, latent).into_iter().map(|s| s / largest).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn feathering_keeps_the_mean_of_a_mask_away_from_its_borders_and_softens_its_edge() {
        let (w, h) = (16, 8);
        let mask: Vec<f64> = (0..w * h).map(|i| if i % w < 8 { 1.0 } else { 0.0 }).collect();
        let soft = feather(&mask, w, h, 3);
        let row = &soft[3 * w..4 * w];
        assert!((row[0] - 1.0).abs() < 1e-12 && row[15] == 0.0, "{row:?}");
        assert!(row[7] > 0.5 && row[7] < 1.0 && row[8] < 0.5 && row[8] > 0.0, "{row:?}");
        assert!((row[7] + row[8] - 1.0).abs() < 1e-12, "symmetric about the edge: {row:?}");
        assert_eq!(feather(&mask, w, h, 0), mask);
    }

    #[test]
    fn an_eightfold_bilinear_reduction_averages_each_blocks_middle_four_pixels() {
        let (w, h) = (16, 8);
        let mask: Vec<f64> = (0..w * h).map(|i| (i % w * 10 + i / w) as f64).collect();
        let small = bilinear(&mask, w, h, 2, 1);
        let at = |y: usize, x: usize| mask[y * w + x];
        let want = (at(3, 3) + at(3, 4) + at(4, 3) + at(4, 4)) / 4.0;
        assert!((small[0] - want).abs() < 1e-12, "{small:?} vs {want}");
    }
}
