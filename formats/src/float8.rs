//! The 8-bit floats safetensors stores as `F8_E4M3` and `F8_E5M2` (torch's `float8_e4m3fn` and
//! `float8_e5m2`, as fp8 checkpoints of SDXL ship their weights), widened to f32. Both are
//! exact in f16 and f32; the runtime rounds nothing further.

use half::f16;

/// `float8_e4m3fn`: sign, 4 exponent bits (bias 7), 3 mantissa bits, no infinities; both
/// `S.1111.111` patterns are NaN.
pub fn e4m3fn_to_f32(byte: u8) -> f32 {
    let sign = if byte & 0x80 != 0 { -1.0 } else { 1.0 };
    let (exponent, mantissa) = (i32::from((byte >> 3) & 0xf), f32::from(byte & 0x7));
    match exponent {
        15 if mantissa == 7.0 => f32::NAN,
        // Subnormal: 2⁻⁶ · m/8.
        0 => sign * mantissa * 2f32.powi(-9),
        e => sign * (1.0 + mantissa / 8.0) * 2f32.powi(e - 7),
    }
}

/// `float8_e5m2`: f16's sign, exponent and top two mantissa bits, so its bits are f16's upper
/// byte (infinities and NaNs included).
pub fn e5m2_to_f32(byte: u8) -> f32 {
    f16::from_bits(u16::from(byte) << 8).to_f32()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn e4m3fn_spans_its_range_without_infinities() {
        assert_eq!(e4m3fn_to_f32(0x00), 0.0);
        assert!(e4m3fn_to_f32(0x80).is_sign_negative() && e4m3fn_to_f32(0x80) == 0.0);
        assert_eq!(e4m3fn_to_f32(0x38), 1.0, "exponent at its bias");
        assert_eq!(e4m3fn_to_f32(0x01), 2f32.powi(-9), "the least subnormal");
        assert_eq!(e4m3fn_to_f32(0x7e), 448.0, "the largest finite");
        assert_eq!(e4m3fn_to_f32(0xfe), -448.0);
        assert!(e4m3fn_to_f32(0x7f).is_nan() && e4m3fn_to_f32(0xff).is_nan());
        assert_eq!(e4m3fn_to_f32(0x78), 256.0, "S.1111.000 is a number, not infinity");
    }

    #[test]
    fn e5m2_is_the_upper_byte_of_f16() {
        assert_eq!(e5m2_to_f32(0x3c), 1.0);
        assert_eq!(e5m2_to_f32(0x7b), 57344.0, "the largest finite");
        assert_eq!(e5m2_to_f32(0x01), 2f32.powi(-16), "the least subnormal");
        assert_eq!(e5m2_to_f32(0x7c), f32::INFINITY);
        assert_eq!(e5m2_to_f32(0xfc), f32::NEG_INFINITY);
        assert!(e5m2_to_f32(0x7d).is_nan());
    }
}
