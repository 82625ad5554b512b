//! libjpeg-turbo's accurate integer inverse DCT (`JDCT_ISLOW`, its default): the Loeffler–
//! Ligtenberg–Moschytz factorisation with 13-bit constants, 2 extra bits between the column and
//! row passes, and its range-limit table, which wraps out-of-range values modulo 1024.

use std::ops::{Add, Mul, Shl, Shr, Sub};

const CONST_BITS: u32 = 13;
const PASS1_BITS: u32 = 2;
const FIX_0_298631336: i32 = 2446;
const FIX_0_390180644: i32 = 3196;
const FIX_0_541196100: i32 = 4433;
const FIX_0_765366865: i32 = 6270;
const FIX_0_899976223: i32 = 7373;
const FIX_1_175875602: i32 = 9633;
const FIX_1_501321110: i32 = 12299;
const FIX_1_847759065: i32 = 15137;
const FIX_1_961570560: i32 = 16069;
const FIX_2_053119869: i32 = 16819;
const FIX_2_562915447: i32 = 20995;
const FIX_3_072711026: i32 = 25172;

/// The arithmetic a pass runs in: i64 as libjpeg-turbo's C code (`JLONG`), or i32, faster, where
/// a block's values are small enough that no intermediate can overflow it (the same results).
trait Lane:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Shl<u32, Output = Self>
    + Shr<u32, Output = Self>
    + From<i32>
{
}
impl Lane for i32 {}
impl Lane for i64 {}

/// (x + 2ⁿ⁻¹) >> n, libjpeg-turbo's `DESCALE`.
fn descale<T: Lane>(x: T, n: u32) -> T {
    (x + (T::from(1) << (n - 1))) >> n
}

/// Every intermediate of `butterfly` is a linear form of its inputs whose coefficients' absolute
/// sum is at most 61 214 (< 2^16; computed over each operation), so inputs under 2^14 keep every
/// value, rounding included, below 2^30.
const I32_SAFE: i32 = 1 << 14;

/// The sample for an IDCT output `x` (before the +128 level shift): libjpeg-turbo's table
/// indexed by `x & 1023`.
fn range_limit<T: Lane>(x: T) -> u8
where
    i64: From<T>,
{
    match (i64::from(x) as i32 & 1023) as u32 {
        i @ 0..=127 => (i + 128) as u8,
        128..=511 => 255,
        512..=895 => 0,
        i => (i - 896) as u8,
    }
}

/// One 1-D pass over eight inputs; returns the eight outputs before descaling.
fn butterfly<T: Lane>(v: [T; 8]) -> [T; 8] {
    let c = |k: i32| T::from(k);
    // Even part.
    let (z2, z3) = (v[2], v[6]);
    let z1 = (z2 + z3) * c(FIX_0_541196100);
    let tmp2 = z1 + z3 * c(-FIX_1_847759065);
    let tmp3 = z1 + z2 * c(FIX_0_765366865);
    let tmp0 = (v[0] + v[4]) << CONST_BITS;
    let tmp1 = (v[0] - v[4]) << CONST_BITS;
    let (tmp10, tmp13, tmp11, tmp12) = (tmp0 + tmp3, tmp0 - tmp3, tmp1 + tmp2, tmp1 - tmp2);
    // Odd part.
    let (t0, t1, t2, t3) = (v[7], v[5], v[3], v[1]);
    let (z1, z2, z3, z4) = (t0 + t3, t1 + t2, t0 + t2, t1 + t3);
    let z5 = (z3 + z4) * c(FIX_1_175875602);
    let (t0, t1, t2, t3) =
        (t0 * c(FIX_0_298631336), t1 * c(FIX_2_053119869), t2 * c(FIX_3_072711026), t3 * c(FIX_1_501321110));
    let (z1, z2) = (z1 * c(-FIX_0_899976223), z2 * c(-FIX_2_562915447));
    let z3 = z3 * c(-FIX_1_961570560) + z5;
    let z4 = z4 * c(-FIX_0_390180644) + z5;
    let (t0, t1, t2, t3) = (t0 + z1 + z3, t1 + z2 + z4, t2 + z2 + z3, t3 + z1 + z4);
    [tmp10 + t3, tmp11 + t2, tmp12 + t1, tmp13 + t0, tmp13 - t0, tmp12 - t1, tmp11 - t2, tmp10 - t3]
}

/// The column pass: the workspace between the passes, C's `int`.
fn columns<T: Lane>(dequantised: &[T; 64]) -> [i32; 64]
where
    i64: From<T>,
{
    let mut workspace = [0i32; 64];
    for col in 0..8 {
        let outs = butterfly::<T>(std::array::from_fn(|r| dequantised[r * 8 + col]));
        for (r, x) in outs.into_iter().enumerate() {
            workspace[r * 8 + col] = i64::from(descale(x, CONST_BITS - PASS1_BITS)) as i32;
        }
    }
    workspace
}

/// The row pass, into samples.
fn rows<T: Lane>(workspace: &[i32; 64], out: &mut [u8], stride: usize)
where
    i64: From<T>,
{
    for (r, w) in workspace.chunks_exact(8).enumerate() {
        let out = &mut out[r * stride..r * stride + 8];
        // A row of zero AC terms is flat (libjpeg-turbo's shortcut, equal to the butterfly's).
        if w[1..].iter().all(|&x| x == 0) {
            out.fill(range_limit(descale(T::from(w[0]), PASS1_BITS + 3)));
            continue;
        }
        let outs = butterfly::<T>(std::array::from_fn(|c| T::from(w[c])));
        for (o, x) in out.iter_mut().zip(outs) {
            *o = range_limit(descale(x, CONST_BITS + PASS1_BITS + 3));
        }
    }
}

/// Inverse-transforms one block (`coefs` and `quant` in natural order) into 8×8 samples at `out`
/// with row stride `stride`.
pub(super) fn idct_islow(coefs: &[i16], quant: &[u16; 64], out: &mut [u8], stride: usize) {
    let small = |x: i64| x.abs() < I32_SAFE as i64;
    let wide: [i64; 64] = std::array::from_fn(|i| coefs[i] as i64 * quant[i] as i64);
    let workspace = if wide.iter().all(|&x| small(x)) { columns(&wide.map(|x| x as i32)) } else { columns(&wide) };
    if workspace.iter().all(|&x| small(x as i64)) {
        rows::<i32>(&workspace, out, stride);
    } else {
        rows::<i64>(&workspace, out, stride);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Extreme blocks just under the bound (all ±(2^14 − 1), alternating and random signs): the
    /// i32 passes give the i64 passes' values.
    #[test]
    fn the_i32_passes_equal_the_i64_ones_under_the_bound() {
        let max = I32_SAFE - 1;
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut sign = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            if state & 1 == 0 {
                1
            } else {
                -1
            }
        };
        let mut blocks: Vec<[i32; 64]> =
            vec![[max; 64], [-max; 64], std::array::from_fn(|i| if i % 2 == 0 { max } else { -max })];
        blocks.extend((0..200).map(|_| std::array::from_fn(|_| sign() * max)));
        for block in blocks {
            assert_eq!(columns(&block), columns(&block.map(i64::from)));
            let (mut narrow, mut wide) = ([0u8; 64], [0u8; 64]);
            rows::<i32>(&block, &mut narrow, 8);
            rows::<i64>(&block, &mut wide, 8);
            assert_eq!(narrow, wide);
        }
    }
}
