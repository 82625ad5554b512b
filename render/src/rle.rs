//! COCO run-length encoding of binary masks, as pycocotools (`common/maskApi.c`) does it:
//! runs over the mask in column-major order, starting with a run of zeros (possibly empty),
//! and the compressed string form of those counts (`rleToString` / `rleFrString`).

use crate::error::{RenderError, Result};

/// An inclusive pixel rectangle: columns x0..=x1, rows y0..=y1.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PixelBox {
    pub x0: u32,
    pub y0: u32,
    pub x1: u32,
    pub y1: u32,
}

impl PixelBox {
    /// COCO's `[x, y, width, height]`.
    pub fn to_xywh(self) -> [u32; 4] {
        [self.x0, self.y0, self.x1 - self.x0 + 1, self.y1 - self.y0 + 1]
    }
}

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Rle {
    pub height: u32,
    pub width: u32,
    /// Alternating run lengths of 0s and 1s, starting with 0s.
    pub counts: Vec<u32>,
}

impl Rle {
    /// The mask of `label` in a row-major label image, reading only `bounds` (which must hold
    /// every pixel of the label).
    pub fn from_labels<T: Copy + PartialEq>(labels: &[T], width: u32, height: u32, label: T, bounds: PixelBox) -> Rle {
        let (w, h) = (width as u64, height as u64);
        let mut counts: Vec<u32> = Vec::new();
        let mut end = 0u64; // column-major position just past the last 1
        for x in bounds.x0..=bounds.x1 {
            for y in bounds.y0..=bounds.y1 {
                if labels[y as usize * width as usize + x as usize] != label {
                    continue;
                }
                let p = x as u64 * h + y as u64;
                match counts.last_mut() {
                    Some(ones) if p == end => *ones += 1,
                    _ => counts.extend([(p - end) as u32, 1]),
                }
                end = p + 1;
            }
        }
        if end < w * h {
            counts.push((w * h - end) as u32);
        }
        Rle { height, width, counts }
    }

    pub fn area(&self) -> u64 {
        self.counts.iter().skip(1).step_by(2).map(|&c| c as u64).sum()
    }

    /// Bounding box of the set pixels, None for an empty mask.
    pub fn bbox(&self) -> Option<PixelBox> {
        let h = self.height as u64;
        let mut bounds: Option<PixelBox> = None;
        let mut p = 0u64;
        for (i, &c) in self.counts.iter().enumerate() {
            if i % 2 == 1 && c > 0 {
                let (first, last) = (p, p + c as u64 - 1);
                let (xa, xb) = ((first / h) as u32, (last / h) as u32);
                // A run that wraps past a column's end covers that column's rows to the bottom
                // and the next one's from the top.
                let (ya, yb) = if xa == xb { ((first % h) as u32, (last % h) as u32) } else { (0, self.height - 1) };
                let b = bounds.get_or_insert(PixelBox { x0: xa, y0: ya, x1: xb, y1: yb });
                *b = PixelBox { x0: b.x0.min(xa), y0: b.y0.min(ya), x1: b.x1.max(xb), y1: b.y1.max(yb) };
            }
            p += c as u64;
        }
        bounds
    }

    /// Row-major mask.
    pub fn to_mask(&self) -> Vec<bool> {
        let (w, h) = (self.width as usize, self.height as usize);
        let mut mask = vec![false; w * h];
        let mut p = 0usize;
        for (i, &c) in self.counts.iter().enumerate() {
            if i % 2 == 1 {
                (p..p + c as usize).for_each(|q| mask[(q % h) * w + q / h] = true);
            }
            p += c as usize;
        }
        mask
    }

    /// pycocotools' compressed counts: each count (from the fourth on, minus the count two
    /// before it) as a little-endian sequence of 5-bit groups, sign-extended from the last group,
    /// 0x20 marking "more groups follow", offset into printable ASCII by 48.
    pub fn to_coco_string(&self) -> String {
        let mut s = String::with_capacity(self.counts.len() * 2);
        for (i, &c) in self.counts.iter().enumerate() {
            let mut x = c as i64 - if i > 2 { self.counts[i - 2] as i64 } else { 0 };
            loop {
                let group = (x & 0x1f) as u8;
                x >>= 5;
                let more = if group & 0x10 != 0 { x != -1 } else { x != 0 };
                s.push(((group | if more { 0x20 } else { 0 }) + 48) as char);
                if !more {
                    break;
                }
            }
        }
        s
    }

    /// Parses pycocotools' compressed counts for a `height`×`width` mask.
    pub fn from_coco_string(s: &str, height: u32, width: u32) -> Result<Rle> {
        let bad =
            |why: &str| RenderError::invalid("RLE counts", s.chars().take(40).collect::<String>(), why.to_string());
        let bytes = s.as_bytes();
        let mut counts: Vec<u32> = Vec::new();
        let mut p = 0;
        while p < bytes.len() {
            let (mut x, mut shift) = (0i64, 0u32);
            loop {
                let c = *bytes.get(p).ok_or_else(|| bad("ends inside a count"))?;
                if !(48..48 + 64).contains(&c) || shift > 55 {
                    return Err(bad("is not a COCO compressed RLE string"));
                }
                let c = (c - 48) as i64;
                x |= (c & 0x1f) << shift;
                p += 1;
                shift += 5;
                if c & 0x20 == 0 {
                    if c & 0x10 != 0 {
                        x |= -1i64 << shift;
                    }
                    break;
                }
            }
            if counts.len() > 2 {
                x += counts[counts.len() - 2] as i64;
            }
            counts.push(u32::try_from(x).map_err(|_| bad("decodes to a negative run"))?);
        }
        let total: u64 = counts.iter().map(|&c| c as u64).sum();
        if total != height as u64 * width as u64 {
            return Err(bad(&format!("covers {total} pixels, not {height}×{width}")));
        }
        Ok(Rle { height, width, counts })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn full(w: u32, h: u32) -> PixelBox {
        PixelBox { x0: 0, y0: 0, x1: w - 1, y1: h - 1 }
    }

    #[test]
    fn column_major_runs_start_with_zeros() {
        // 3 wide, 2 tall; label 1 at (0,0), (1,0), (1,1): column-major 1,0 | 1,1 | 0,0.
        let labels = [1u8, 1, 0, 0, 1, 0];
        let rle = Rle::from_labels(&labels, 3, 2, 1, full(3, 2));
        assert_eq!(rle.counts, vec![0, 1, 1, 2, 2]);
        assert_eq!(rle.area(), 3);
        assert_eq!(rle.bbox(), Some(PixelBox { x0: 0, y0: 0, x1: 1, y1: 1 }));
        assert_eq!(rle.to_mask(), labels.map(|l| l == 1).to_vec());
        let none = Rle::from_labels(&labels, 3, 2, 7, full(3, 2));
        assert_eq!((none.bbox(), none.counts), (None, vec![6]));
    }

    #[test]
    fn strings_round_trip_including_large_and_shrinking_runs() {
        let counts = vec![0, 1, 31, 16, 70_000, 3, 5, 1_000_000, 2, 0x7fff_ffff];
        let total: u64 = counts.iter().map(|&c| c as u64).sum();
        let rle = Rle { height: 1, width: total as u32, counts };
        let s = rle.to_coco_string();
        assert!(s.bytes().all(|b| (48..112).contains(&b)));
        assert_eq!(Rle::from_coco_string(&s, 1, total as u32).unwrap(), rle);
    }

    #[test]
    fn malformed_strings_are_errors() {
        assert!(Rle::from_coco_string("0", 2, 2).is_err(), "wrong total");
        assert!(Rle::from_coco_string("P", 1, 1).is_err(), "dangling continuation");
        assert!(Rle::from_coco_string("~", 1, 1).is_err(), "outside the alphabet");
    }
}
