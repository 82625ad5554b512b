//! Huffman-coded scan data to DCT coefficients, sequential and progressive, with libjpeg-turbo's
//! behaviour where the data is short or damaged: a scan that meets a marker early reads zero bits
//! for the block in hand and leaves the rest of its restart interval untouched; a code that is
//! in no table reads as symbol 0; misplaced restart markers are resynchronised as
//! `jpeg_resync_to_restart` does.

use super::frame::{Frame, Scan};

pub(super) const TRUNCATED: &str = "truncated JPEG: the file ends before the image is complete";

/// Natural (row-major) position of the k-th zig-zag coefficient; past 63 (a corrupt run length)
/// libjpeg-turbo writes to the last coefficient, and so do we.
const NATURAL_ORDER: [usize; 80] = {
    let zigzag: [usize; 64] = [
        0, 1, 8, 16, 9, 2, 3, 10, 17, 24, 32, 25, 18, 11, 4, 5, 12, 19, 26, 33, 40, 48, 41, 34, 27, 20, 13, 6, 7, 14,
        21, 28, 35, 42, 49, 56, 57, 50, 43, 36, 29, 22, 15, 23, 30, 37, 44, 51, 58, 59, 52, 45, 38, 31, 39, 46, 53, 60,
        61, 54, 47, 55, 62, 63,
    ];
    let mut order = [63; 80];
    let mut k = 0;
    while k < 64 {
        order[k] = zigzag[k];
        k += 1;
    }
    order
};

pub(super) fn natural_order(k: usize) -> usize {
    NATURAL_ORDER[k.min(79)]
}

/// The position of the next marker at or after `pos` (garbage and fill bytes skipped, as
/// libjpeg-turbo's `next_marker` does) and its code, with `pos` moved past it; None at the end.
pub(super) fn next_marker(data: &[u8], pos: &mut usize) -> Option<u8> {
    loop {
        while *data.get(*pos)? != 0xFF {
            *pos += 1;
        }
        while *data.get(*pos)? == 0xFF {
            *pos += 1;
        }
        let code = data[*pos];
        *pos += 1;
        if code != 0 {
            return Some(code);
        }
    }
}

/// libjpeg-turbo's bit buffer (64 bits, refilled to at least 57 when it runs low).
pub(super) struct BitReader<'a> {
    data: &'a [u8],
    pub pos: usize,
    /// Left-aligned: the next bit is bit 63; bits below the top `count` are zero.
    bits: u64,
    count: u32,
    /// A marker met inside the data (libjpeg-turbo's `unread_marker`): from here on, zero bits.
    pub marker: Option<u8>,
    /// Bits were needed past that marker: the rest of the restart interval is skipped.
    pub insufficient: bool,
}

const MIN_GET_BITS: u32 = 57;

impl<'a> BitReader<'a> {
    pub fn new(data: &'a [u8], pos: usize) -> Self {
        BitReader { data, pos, bits: 0, count: 0, marker: None, insufficient: false }
    }

    fn byte(&mut self) -> Result<u8, String> {
        let b = *self.data.get(self.pos).ok_or(TRUNCATED)?;
        self.pos += 1;
        Ok(b)
    }

    /// `jpeg_fill_bit_buffer`: the end of the file where data should be is an error (Pillow gives
    /// libjpeg-turbo nothing more, and raises "image file is truncated").
    fn fill(&mut self, need: u32) -> Result<(), String> {
        if self.marker.is_none() {
            while self.count < MIN_GET_BITS {
                let mut b = self.byte()?;
                if b == 0xFF {
                    let mut c = self.byte()?;
                    while c == 0xFF {
                        c = self.byte()?;
                    }
                    if c != 0 {
                        self.marker = Some(c);
                        break;
                    }
                    b = 0xFF;
                }
                self.bits |= (b as u64) << (56 - self.count);
                self.count += 8;
            }
        }
        if self.count < need {
            self.insufficient = true;
            self.count = MIN_GET_BITS;
        }
        Ok(())
    }

    fn take(&mut self, n: u32) -> u32 {
        let v = (self.bits >> (64 - n)) as u32;
        self.bits <<= n;
        self.count -= n;
        v
    }

    pub fn bits(&mut self, n: u32) -> Result<u32, String> {
        if n == 0 {
            return Ok(0);
        }
        if self.count < n {
            self.fill(n)?;
        }
        Ok(self.take(n))
    }

    /// A coefficient's `s` extra bits, sign-extended (`HUFF_EXTEND`).
    fn extended(&mut self, s: u32) -> Result<i32, String> {
        let v = self.bits(s)? as i32;
        Ok(if s > 0 && v < 1 << (s - 1) { v - (1 << s) + 1 } else { v })
    }

    /// Drops the buffered bits before a restart marker.
    fn clear(&mut self) {
        self.bits = 0;
        self.count = 0;
    }
}

/// A Huffman table prepared for decoding (`jpeg_make_d_derived_tbl`).
#[derive(Clone)]
pub(super) struct Huffman {
    /// Largest code of each length 1..=16 (-1: none); [17] is a sentinel.
    maxcode: [i32; 18],
    /// Symbol index minus code, per length.
    valoffset: [i32; 17],
    values: [u8; 256],
    /// For the next 8 bits: (code length, symbol), length 0 when the code is longer.
    lookup: [(u8, u8); 256],
}

impl Huffman {
    /// From a DHT entry: 16 code-length counts and the symbols.
    pub fn new(counts: &[u8; 16], symbols: &[u8], is_dc: bool) -> Result<Huffman, String> {
        let bad = || "bad Huffman table".to_string();
        if symbols.len() > 256 || (is_dc && symbols.iter().any(|&s| s > 15)) {
            return Err(bad());
        }
        let mut values = [0u8; 256];
        values[..symbols.len()].copy_from_slice(symbols);
        let (mut maxcode, mut valoffset, mut lookup) = ([-1i32; 18], [0i32; 17], [(0u8, 0u8); 256]);
        let (mut code, mut index) = (0i32, 0usize);
        for len in 1..=16 {
            let n = counts[len - 1] as usize;
            if n > 0 {
                valoffset[len] = index as i32 - code;
                for i in 0..n {
                    if len <= 8 {
                        let shift = 8 - len;
                        for fill in 0..1usize << shift {
                            lookup[((code as usize) << shift) | fill] = (len as u8, values[index + i]);
                        }
                    }
                    code += 1;
                }
                index += n;
                maxcode[len] = code - 1;
            }
            // A complete code of this length must still fit in `len` bits.
            if code > 1 << len {
                return Err(bad());
            }
            code <<= 1;
        }
        maxcode[17] = 0xFFFFF;
        Ok(Huffman { maxcode, valoffset, values, lookup })
    }

    /// The next symbol (`HUFF_DECODE`, then `jpeg_huff_decode` for codes over 8 bits).
    fn decode(&self, r: &mut BitReader) -> Result<u32, String> {
        if r.count < 8 {
            r.fill(0)?;
        }
        let mut len = 1;
        if r.count >= 8 {
            let (l, symbol) = self.lookup[(r.bits >> 56) as usize];
            if l > 0 {
                r.take(l as u32);
                return Ok(symbol as u32);
            }
            len = 9;
        }
        let mut code = r.bits(len)? as i32;
        while code > self.maxcode[len as usize] {
            code = (code << 1) | r.bits(1)? as i32;
            len += 1;
        }
        if len > 16 {
            return Ok(0); // "Corrupt JPEG data: bad Huffman code"
        }
        Ok(self.values[((code + self.valoffset[len as usize]) & 0xFF) as usize] as u32)
    }
}

/// The tables a scan reads, per component of the scan.
pub(super) struct ScanTables<'t> {
    pub dc: Vec<Option<&'t Huffman>>,
    pub ac: Vec<Option<&'t Huffman>>,
}

struct State {
    dc_pred: [i32; 4],
    eobrun: u32,
}

/// Decodes one scan from `pos` into the frame's coefficients. Returns where the data stopped and
/// the marker that stopped it, if one was met inside the data.
pub(super) fn decode_scan(
    frame: &mut Frame,
    scan: &Scan,
    tables: &ScanTables,
    restart_interval: usize,
    data: &[u8],
    pos: usize,
) -> Result<(usize, Option<u8>), String> {
    let mut r = BitReader::new(data, pos);
    let mut state = State { dc_pred: [0; 4], eobrun: 0 };
    let single = scan.components.len() == 1;
    let (mcus_x, mcus_y) = if single {
        let c = &frame.components[scan.components[0]];
        (c.width_in_blocks, c.height_in_blocks)
    } else {
        (frame.mcus_x, frame.mcus_y)
    };
    let (mut restarts_to_go, mut next_restart) = (restart_interval, 0u8);
    for my in 0..mcus_y {
        for mx in 0..mcus_x {
            if restart_interval > 0 && restarts_to_go == 0 {
                restart(&mut r, &mut next_restart)?;
                state = State { dc_pred: [0; 4], eobrun: 0 };
                restarts_to_go = restart_interval;
            }
            if !r.insufficient {
                for (si, &ci) in scan.components.iter().enumerate() {
                    let comp = &mut frame.components[ci];
                    let (h, v) = if single { (1, 1) } else { (comp.h, comp.v) };
                    for by in 0..v {
                        for bx in 0..h {
                            let block = comp.block_mut(mx * h + bx, my * v + by);
                            decode_block(&mut r, scan, tables, si, block, &mut state, frame.progressive)?;
                        }
                    }
                }
            }
            restarts_to_go = restarts_to_go.wrapping_sub(1);
        }
    }
    Ok((r.pos, r.marker))
}

fn table(t: Option<&Huffman>) -> Result<&Huffman, String> {
    t.ok_or_else(|| "a scan uses a Huffman table the file does not define".to_string())
}

fn decode_block(
    r: &mut BitReader,
    scan: &Scan,
    tables: &ScanTables,
    si: usize,
    block: &mut [i16],
    state: &mut State,
    progressive: bool,
) -> Result<(), String> {
    if !progressive {
        decode_dc_first(r, table(tables.dc[si])?, block, &mut state.dc_pred[si], 0)?;
        return decode_ac_first(r, table(tables.ac[si])?, block, None, 1, 63, 0);
    }
    match (scan.ss, scan.ah) {
        (0, 0) => decode_dc_first(r, table(tables.dc[si])?, block, &mut state.dc_pred[si], scan.al),
        (0, _) => {
            if r.bits(1)? != 0 {
                block[0] |= 1 << scan.al;
            }
            Ok(())
        }
        (ss, 0) => decode_ac_first(r, table(tables.ac[si])?, block, Some(&mut state.eobrun), ss, scan.se, scan.al),
        (ss, _) => decode_ac_refine(r, table(tables.ac[si])?, block, &mut state.eobrun, ss, scan.se, scan.al),
    }
}

fn decode_dc_first(r: &mut BitReader, dc: &Huffman, block: &mut [i16], pred: &mut i32, al: u32) -> Result<(), String> {
    let s = dc.decode(r)?;
    let diff = r.extended(s)?;
    *pred = pred.wrapping_add(diff);
    block[0] = (*pred << al) as i16;
    Ok(())
}

/// Progressive first AC scans, and sequential blocks (coefficients 1..=63, no end-of-band runs:
/// `eobrun` None).
fn decode_ac_first(
    r: &mut BitReader,
    ac: &Huffman,
    block: &mut [i16],
    mut eobrun: Option<&mut u32>,
    ss: usize,
    se: usize,
    al: u32,
) -> Result<(), String> {
    if let Some(run) = eobrun.as_deref_mut().filter(|run| **run > 0) {
        *run -= 1;
        return Ok(());
    }
    let mut k = ss;
    while k <= se {
        let rs = ac.decode(r)?;
        let (run, size) = (rs >> 4, rs & 15);
        if size != 0 {
            k += run as usize;
            let v = r.extended(size)?;
            block[natural_order(k)] = (v << al) as i16;
        } else if run == 15 {
            k += 15;
        } else {
            if let Some(eobrun) = eobrun {
                *eobrun = (1 << run) + r.bits(run)? - 1;
            }
            break;
        }
        k += 1;
    }
    Ok(())
}

/// One correction bit for an already nonzero coefficient.
fn refine(r: &mut BitReader, coef: &mut i16, p1: i16) -> Result<(), String> {
    if r.bits(1)? != 0 && *coef & p1 == 0 {
        *coef = if *coef >= 0 { coef.wrapping_add(p1) } else { coef.wrapping_sub(p1) };
    }
    Ok(())
}

fn decode_ac_refine(
    r: &mut BitReader,
    ac: &Huffman,
    block: &mut [i16],
    eobrun: &mut u32,
    ss: usize,
    se: usize,
    al: u32,
) -> Result<(), String> {
    let p1 = (1i32 << al) as i16;
    let mut k = ss;
    if *eobrun == 0 {
        while k <= se {
            let rs = ac.decode(r)?;
            let (mut run, size) = ((rs >> 4) as i32, rs & 15);
            let mut value = 0i16;
            if size != 0 {
                // A newly nonzero coefficient is ±1 in this bit (libjpeg-turbo warns if size > 1).
                value = if r.bits(1)? != 0 { p1 } else { -p1 };
            } else if run != 15 {
                *eobrun = (1u32 << run) + r.bits(run as u32)?;
                break;
            }
            while k <= se {
                let coef = &mut block[natural_order(k)];
                if *coef != 0 {
                    refine(r, coef, p1)?;
                } else {
                    run -= 1;
                    if run < 0 {
                        break;
                    }
                }
                k += 1;
            }
            if value != 0 {
                block[natural_order(k)] = value;
            }
            k += 1;
        }
    }
    if *eobrun > 0 {
        while k <= se {
            let coef = &mut block[natural_order(k)];
            if *coef != 0 {
                refine(r, coef, p1)?;
            }
            k += 1;
        }
        *eobrun -= 1;
    }
    Ok(())
}

/// `process_restart` and `read_restart_marker`: the buffered bits are dropped and the expected
/// RSTn is read; any other marker is resolved as `jpeg_resync_to_restart` resolves it.
fn restart(r: &mut BitReader, next: &mut u8) -> Result<(), String> {
    r.clear();
    let mut marker = match r.marker.take() {
        Some(m) => m,
        None => next_marker(r.data, &mut r.pos).ok_or(TRUNCATED)?,
    };
    let expected = 0xD0 + *next;
    if marker != expected {
        loop {
            let rst = marker.wrapping_sub(0xD0) as u32;
            let d = *next as u32;
            let action = if marker < 0xC0 {
                2
            } else if !(0xD0..=0xD7).contains(&marker) || rst == (d + 1) & 7 || rst == (d + 2) & 7 {
                3
            } else if rst == (d + 7) & 7 || rst == (d + 6) & 7 {
                2
            } else {
                1
            };
            match action {
                1 => break,
                2 => marker = next_marker(r.data, &mut r.pos).ok_or(TRUNCATED)?,
                _ => {
                    // Left unread: the entropy decoder reads zeros up to it.
                    r.marker = Some(marker);
                    break;
                }
            }
        }
    }
    if r.marker.is_none() {
        r.insufficient = false;
    }
    *next = (*next + 1) & 7;
    Ok(())
}
