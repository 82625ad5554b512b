//! The boundaries the masks have, as a ControlNet's edge control: 1-pixel white lines on black
//! where the instance id changes or the depth jumps, computed from the labels rather than guessed
//! by a Canny filter from an image.

/// Where the depth jumps by more than this fraction of the nearer side, by default.
pub const DEFAULT_DEPTH_JUMP: f32 = 0.05;

/// How far apart two depths are, as a fraction of the nearer one: 0 for equal depths (two pixels
/// at infinity among them), ∞ where only one is infinite.
fn relative_jump(a: f32, b: f32) -> f32 {
    if a == b {
        0.0
    } else if a.is_infinite() || b.is_infinite() {
        f32::INFINITY
    } else {
        (a - b).abs() / a.min(b)
    }
}

/// RGB8 edges of a `width`-wide frame's `ids` (0 background) and planar `depth` (+∞ where nothing
/// was drawn). Two 4-neighbours meet at a boundary where their ids differ or their depths differ by
/// more than `depth_jump` (relative); the line is drawn on the nearer side (at equal depths, the
/// larger id's), so it lies on the outermost pixels of the object in front, its mask's own boundary,
/// one pixel wide. The frame's border is no boundary.
pub fn edge_image(ids: &[u16], depth: &[f32], width: usize, depth_jump: f32) -> Vec<u8> {
    let height = ids.len().checked_div(width).unwrap_or(0);
    let in_front = |p: usize, q: usize| {
        let boundary = ids[p] != ids[q] || relative_jump(depth[p], depth[q]) > depth_jump;
        boundary && (depth[p] < depth[q] || (depth[p] == depth[q] && ids[p] > ids[q]))
    };
    let mut out = vec![0u8; ids.len() * 3];
    for y in 0..height {
        for x in 0..width {
            let p = y * width + x;
            let neighbours = [
                (x > 0).then(|| p - 1),
                (x + 1 < width).then(|| p + 1),
                (y > 0).then(|| p - width),
                (y + 1 < height).then(|| p + width),
            ];
            if neighbours.into_iter().flatten().any(|q| in_front(p, q)) {
                out[p * 3..p * 3 + 3].fill(255);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lit(image: &[u8]) -> Vec<bool> {
        image.chunks(3).map(|px| px == [255, 255, 255]).collect()
    }

    #[test]
    fn the_line_lies_on_the_nearer_side_one_pixel_wide() {
        // A 2-pixel object (id 1, 1 m) on a floor (id 0, 2 m), and sky beyond the floor.
        let ids = [0, 1, 1, 0, 0];
        let depth = [2.0, 1.0, 1.0, 2.0, f32::INFINITY];
        assert_eq!(lit(&edge_image(&ids, &depth, 5, DEFAULT_DEPTH_JUMP)), [false, true, true, true, false]);
        // Touching instances at one depth: the larger id's side only.
        assert_eq!(lit(&edge_image(&[1, 2], &[1.0, 1.0], 2, DEFAULT_DEPTH_JUMP)), [false, true]);
        // A jump within one instance counts above the threshold only.
        assert_eq!(lit(&edge_image(&[1, 1], &[1.0, 1.04], 2, 0.05)), [false, false]);
        assert_eq!(lit(&edge_image(&[1, 1], &[1.0, 1.06], 2, 0.05)), [true, false]);
    }
}
