//! Host-side conversions between PyTorch's NCHW and vkdiff's channels-last activations.

/// [N, C, H, W] → [N, H, W, C].
pub fn nchw_to_nhwc(x: &[f32], [n, c, h, w]: [usize; 4]) -> Vec<f32> {
    let mut out = vec![0.0; x.len()];
    for b in 0..n {
        for ch in 0..c {
            for p in 0..h * w {
                out[(b * h * w + p) * c + ch] = x[(b * c + ch) * h * w + p];
            }
        }
    }
    out
}

/// [N, H, W, C] → [N, C, H, W].
pub fn nhwc_to_nchw(x: &[f32], [n, h, w, c]: [usize; 4]) -> Vec<f32> {
    let mut out = vec![0.0; x.len()];
    for b in 0..n {
        for p in 0..h * w {
            for ch in 0..c {
                out[(b * c + ch) * h * w + p] = x[(b * h * w + p) * c + ch];
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_one_known_element() {
        let x: Vec<f32> = (0..2 * 3 * 4 * 5).map(|i| i as f32).collect();
        let nhwc = nchw_to_nhwc(&x, [2, 3, 4, 5]);
        // Element (b=1, c=2, y=3, x=4) of NCHW sits at ((1·4 + 3)·5 + 4)·3 + 2 in NHWC.
        assert_eq!(nhwc[((4 + 3) * 5 + 4) * 3 + 2], x[((3 + 2) * 4 + 3) * 5 + 4]);
        assert_eq!(nhwc_to_nchw(&nhwc, [2, 4, 5, 3]), x);
    }
}
