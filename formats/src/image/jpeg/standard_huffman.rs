//! The Huffman tables of ITU-T T.81 Annex K.3 (luminance and chrominance, DC and AC), which
//! libjpeg-turbo substitutes when a sequential file defines none: motion-JPEG frames leave them
//! out.

use super::entropy::Huffman;

/// Code-length counts (lengths 1..=16) of tables K.3 to K.6.
const DC_LUMINANCE_COUNTS: [u8; 16] = [0, 1, 5, 1, 1, 1, 1, 1, 1, 0, 0, 0, 0, 0, 0, 0];
const DC_CHROMINANCE_COUNTS: [u8; 16] = [0, 3, 1, 1, 1, 1, 1, 1, 1, 1, 1, 0, 0, 0, 0, 0];
const AC_LUMINANCE_COUNTS: [u8; 16] = [0, 2, 1, 3, 3, 2, 4, 3, 5, 5, 4, 4, 0, 0, 1, 0x7d];
const AC_CHROMINANCE_COUNTS: [u8; 16] = [0, 2, 1, 2, 4, 4, 3, 4, 7, 5, 4, 4, 0, 1, 2, 0x77];

/// The AC symbols with short codes, in code order; every other (run, size) symbol follows in
/// ascending order (tables K.5 and K.6 are built that way).
const AC_LUMINANCE_HEAD: [u8; 37] = [
    0x01, 0x02, 0x03, 0x00, 0x04, 0x11, 0x05, 0x12, 0x21, 0x31, 0x41, 0x06, 0x13, 0x51, 0x61, 0x07, 0x22, 0x71, 0x14,
    0x32, 0x81, 0x91, 0xa1, 0x08, 0x23, 0x42, 0xb1, 0xc1, 0x15, 0x52, 0xd1, 0xf0, 0x24, 0x33, 0x62, 0x72, 0x82,
];
const AC_CHROMINANCE_HEAD: [u8; 43] = [
    0x00, 0x01, 0x02, 0x03, 0x11, 0x04, 0x05, 0x21, 0x31, 0x06, 0x12, 0x41, 0x51, 0x07, 0x61, 0x71, 0x13, 0x22, 0x32,
    0x81, 0x08, 0x14, 0x42, 0x91, 0xa1, 0xb1, 0xc1, 0x09, 0x23, 0x33, 0x52, 0xf0, 0x15, 0x62, 0x72, 0xd1, 0x0a, 0x16,
    0x24, 0x34, 0xe1, 0x25, 0xf1,
];

fn ac_symbols(head: &[u8]) -> Vec<u8> {
    let valid = |s: &u8| matches!(s & 15, 1..=10) || *s == 0x00 || *s == 0xf0;
    let rest = (0..=255u8).filter(valid).filter(|s| !head.contains(s));
    head.iter().copied().chain(rest).collect()
}

/// Standard table `slot` (0 luminance, 1 chrominance) of the DC or AC class.
pub(super) fn standard_table(is_dc: bool, slot: usize) -> Huffman {
    let dc_symbols: Vec<u8> = (0..12).collect();
    let (counts, symbols) = match (is_dc, slot) {
        (true, 0) => (DC_LUMINANCE_COUNTS, dc_symbols),
        (true, _) => (DC_CHROMINANCE_COUNTS, dc_symbols),
        (false, 0) => (AC_LUMINANCE_COUNTS, ac_symbols(&AC_LUMINANCE_HEAD)),
        (false, _) => (AC_CHROMINANCE_COUNTS, ac_symbols(&AC_CHROMINANCE_HEAD)),
    };
    Huffman::new(&counts, &symbols, is_dc).expect("the standard tables are valid")
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_ac_tables_hold_all_162_symbols() {
        for head in [&super::AC_LUMINANCE_HEAD[..], &super::AC_CHROMINANCE_HEAD[..]] {
            assert_eq!(super::ac_symbols(head).len(), 162);
        }
    }
}
