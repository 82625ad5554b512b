//! libjpeg-turbo's accurate integer inverse DCT (`JDCT_ISLOW`, its default): the Loeffler–
//! Ligtenberg–Moschytz factorisation with 13-bit constants, 2 extra bits between the column and
//! row passes, and its range-limit table, which wraps out-of-range values modulo 1024.

const CONST_BITS: u32 = 13;
const PASS1_BITS: u32 = 2;
const FIX_0_298631336: i64 = 2446;
const FIX_0_390180644: i64 = 3196;
const FIX_0_541196100: i64 = 4433;
const FIX_0_765366865: i64 = 6270;
const FIX_0_899976223: i64 = 7373;
const FIX_1_175875602: i64 = 9633;
const FIX_1_501321110: i64 = 12299;
const FIX_1_847759065: i64 = 15137;
const FIX_1_961570560: i64 = 16069;
const FIX_2_053119869: i64 = 16819;
const FIX_2_562915447: i64 = 20995;
const FIX_3_072711026: i64 = 25172;

fn descale(x: i64, n: u32) -> i64 {
    (x + (1 << (n - 1))) >> n
}

/// The sample for an IDCT output `x` (before the +128 level shift): libjpeg-turbo's table
/// indexed by `x & 1023`.
fn range_limit(x: i64) -> u8 {
    match (x as i32 & 1023) as u32 {
        i @ 0..=127 => (i + 128) as u8,
        128..=511 => 255,
        512..=895 => 0,
        i => (i - 896) as u8,
    }
}

/// One 1-D pass over eight values `v[0..8]` (already dequantised / from the first pass); returns
/// the eight outputs before descaling.
fn butterfly(v: [i64; 8]) -> [i64; 8] {
    // Even part.
    let (z2, z3) = (v[2], v[6]);
    let z1 = (z2 + z3) * FIX_0_541196100;
    let tmp2 = z1 + z3 * -FIX_1_847759065;
    let tmp3 = z1 + z2 * FIX_0_765366865;
    let tmp0 = (v[0] + v[4]) << CONST_BITS;
    let tmp1 = (v[0] - v[4]) << CONST_BITS;
    let (tmp10, tmp13, tmp11, tmp12) = (tmp0 + tmp3, tmp0 - tmp3, tmp1 + tmp2, tmp1 - tmp2);
    // Odd part.
    let (t0, t1, t2, t3) = (v[7], v[5], v[3], v[1]);
    let (z1, z2, z3, z4) = (t0 + t3, t1 + t2, t0 + t2, t1 + t3);
    let z5 = (z3 + z4) * FIX_1_175875602;
    let (t0, t1, t2, t3) = (t0 * FIX_0_298631336, t1 * FIX_2_053119869, t2 * FIX_3_072711026, t3 * FIX_1_501321110);
    let (z1, z2) = (z1 * -FIX_0_899976223, z2 * -FIX_2_562915447);
    let z3 = z3 * -FIX_1_961570560 + z5;
    let z4 = z4 * -FIX_0_390180644 + z5;
    let (t0, t1, t2, t3) = (t0 + z1 + z3, t1 + z2 + z4, t2 + z2 + z3, t3 + z1 + z4);
    [tmp10 + t3, tmp11 + t2, tmp12 + t1, tmp13 + t0, tmp13 - t0, tmp12 - t1, tmp11 - t2, tmp10 - t3]
}

/// Inverse-transforms one block (`coefs` and `quant` in natural order) into 8×8 samples at `out`
/// with row stride `stride`.
pub(super) fn idct_islow(coefs: &[i16], quant: &[u16; 64], out: &mut [u8], stride: usize) {
    let mut workspace = [0i32; 64];
    for col in 0..8 {
        let v: [i64; 8] = std::array::from_fn(|row| coefs[row * 8 + col] as i64 * quant[row * 8 + col] as i64);
        // A column of zero AC terms is its DC term throughout (what the butterfly gives, faster).
        let outs = if v[1..].iter().all(|&x| x == 0) { [v[0] << CONST_BITS; 8] } else { butterfly(v) };
        for row in 0..8 {
            workspace[row * 8 + col] = descale(outs[row], CONST_BITS - PASS1_BITS) as i32;
        }
    }
    for (row, w) in workspace.chunks_exact(8).enumerate() {
        let out = &mut out[row * stride..row * stride + 8];
        // A row of zero AC terms is flat (libjpeg-turbo's shortcut, equal to the butterfly's).
        if w[1..].iter().all(|&x| x == 0) {
            out.fill(range_limit(descale(w[0] as i64, PASS1_BITS + 3)));
            continue;
        }
        let outs = butterfly(std::array::from_fn(|col| w[col] as i64));
        for (o, v) in out.iter_mut().zip(outs) {
            *o = range_limit(descale(v, CONST_BITS + PASS1_BITS + 3));
        }
    }
}
