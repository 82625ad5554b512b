//! The marker stream: tables, the frame header and its components, and each scan handed to the
//! entropy decoder, with libjpeg-turbo's rules for what ends the image and which colour space it is.

use super::entropy::{decode_scan, next_marker, Huffman, ScanTables, TRUNCATED};
use super::standard_huffman::standard_table;
use super::MAX_PIXELS;

pub(super) struct Component {
    pub id: u8,
    pub h: usize,
    pub v: usize,
    quant_slot: usize,
    /// The quantisation table (natural order), latched when the component's first scan starts,
    /// as libjpeg-turbo does; None if no scan holds the component.
    pub quant: Option<[u16; 64]>,
    /// Blocks that hold image samples.
    pub width_in_blocks: usize,
    pub height_in_blocks: usize,
    /// Blocks allocated: whole MCUs.
    pub blocks_w: usize,
    /// Coefficients, 64 a block in natural order, blocks row by row.
    pub coefs: Vec<i16>,
}

impl Component {
    pub fn block_mut(&mut self, bx: usize, by: usize) -> &mut [i16] {
        let at = (by * self.blocks_w + bx) * 64;
        &mut self.coefs[at..at + 64]
    }

    pub fn block(&self, bx: usize, by: usize) -> &[i16] {
        let at = (by * self.blocks_w + bx) * 64;
        &self.coefs[at..at + 64]
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum ColorSpace {
    Grey,
    YCbCr,
    Rgb,
    Cmyk,
    Ycck,
}

pub(super) struct Frame {
    pub width: usize,
    pub height: usize,
    pub progressive: bool,
    pub components: Vec<Component>,
    pub max_h: usize,
    pub max_v: usize,
    pub mcus_x: usize,
    pub mcus_y: usize,
    pub color: ColorSpace,
}

/// A scan header: which components (indices into the frame's), the Huffman table slots, and the
/// progressive band and bit position.
pub(super) struct Scan {
    pub components: Vec<usize>,
    dc_slots: Vec<usize>,
    ac_slots: Vec<usize>,
    pub ss: usize,
    pub se: usize,
    pub ah: u32,
    pub al: u32,
}

#[derive(Default)]
struct Tables {
    quant: [Option<[u16; 64]>; 4],
    dc: [Option<Huffman>; 4],
    ac: [Option<Huffman>; 4],
    restart_interval: usize,
}

fn u16_at(s: &[u8], i: usize) -> usize {
    u16::from_be_bytes([s[i], s[i + 1]]) as usize
}

/// A marker segment's payload (after its length), with `pos` moved past it.
fn segment<'a>(data: &'a [u8], pos: &mut usize) -> Result<&'a [u8], String> {
    let len = data.get(*pos..*pos + 2).map(|b| u16_at(b, 0)).ok_or(TRUNCATED)?;
    if len < 2 {
        return Err(format!("bad JPEG marker segment length {len}"));
    }
    let body = data.get(*pos + 2..*pos + len).ok_or(TRUNCATED)?;
    *pos += len;
    Ok(body)
}

impl Tables {
    /// libjpeg-turbo's `std_huff_tables` when its sequential decoder starts: slots 0 and 1 that
    /// no table was given for get Annex K's.
    fn fill_standard_huffman(&mut self) {
        for slot in 0..2 {
            self.dc[slot].get_or_insert_with(|| standard_table(true, slot));
            self.ac[slot].get_or_insert_with(|| standard_table(false, slot));
        }
    }

    fn read_quant(&mut self, mut s: &[u8]) -> Result<(), String> {
        while !s.is_empty() {
            let (precision, slot) = (s[0] >> 4, (s[0] & 15) as usize);
            let size = if precision == 0 { 64 } else { 128 };
            if slot > 3 || precision > 1 || s.len() < 1 + size {
                return Err("bad JPEG quantisation table".into());
            }
            let mut table = [0u16; 64];
            for k in 0..64 {
                let v = if precision == 0 { s[1 + k] as u16 } else { u16_at(s, 1 + 2 * k) as u16 };
                table[super::entropy::natural_order(k)] = v;
            }
            self.quant[slot] = Some(table);
            s = &s[1 + size..];
        }
        Ok(())
    }

    fn read_huffman(&mut self, mut s: &[u8]) -> Result<(), String> {
        while !s.is_empty() {
            if s.len() < 17 {
                return Err("bad JPEG Huffman table".into());
            }
            let (class, slot) = (s[0] >> 4, (s[0] & 15) as usize);
            let counts: [u8; 16] = s[1..17].try_into().expect("16 bytes");
            let n: usize = counts.iter().map(|&c| c as usize).sum();
            if class > 1 || slot > 3 || s.len() < 17 + n {
                return Err("bad JPEG Huffman table".into());
            }
            let table = Huffman::new(&counts, &s[17..17 + n], class == 0)?;
            if class == 0 {
                self.dc[slot] = Some(table);
            } else {
                self.ac[slot] = Some(table);
            }
            s = &s[17 + n..];
        }
        Ok(())
    }
}

fn sof_kind(marker: u8) -> &'static str {
    match marker {
        0xC3 => "lossless",
        0xC5..=0xC7 => "hierarchical",
        _ => "arithmetic-coded",
    }
}

impl Frame {
    fn parse(s: &[u8], progressive: bool) -> Result<Frame, String> {
        if s.len() < 6 {
            return Err("bad JPEG frame header".into());
        }
        if s[0] != 8 {
            return Err(format!("{}-bit JPEG samples (only 8-bit JPEG is read, as by Pillow)", s[0]));
        }
        let (height, width, n) = (u16_at(s, 1), u16_at(s, 3), s[5] as usize);
        if width == 0 || height == 0 {
            return Err("JPEG of zero width or height (a DNL marker is not supported)".into());
        }
        if (width as u64) * (height as u64) > MAX_PIXELS {
            return Err(format!("{width}x{height} JPEG: more pixels than Pillow opens ({MAX_PIXELS})"));
        }
        if !matches!(n, 1 | 3 | 4) || s.len() < 6 + 3 * n {
            return Err(format!("JPEG with {n} components (1, 3 or 4 are read)"));
        }
        let mut components = Vec::with_capacity(n);
        for c in s[6..6 + 3 * n].chunks_exact(3) {
            let (h, v) = ((c[1] >> 4) as usize, (c[1] & 15) as usize);
            if !(1..=4).contains(&h) || !(1..=4).contains(&v) || c[2] > 3 {
                return Err("bad JPEG sampling factors or quantisation table number".into());
            }
            let placeholder = Component {
                id: c[0],
                h,
                v,
                quant_slot: c[2] as usize,
                quant: None,
                width_in_blocks: 0,
                height_in_blocks: 0,
                blocks_w: 0,
                coefs: Vec::new(),
            };
            components.push(placeholder);
        }
        let max_h = components.iter().map(|c| c.h).max().expect("components");
        let max_v = components.iter().map(|c| c.v).max().expect("components");
        let (mcus_x, mcus_y) = (width.div_ceil(8 * max_h), height.div_ceil(8 * max_v));
        for c in &mut components {
            c.width_in_blocks = (width * c.h).div_ceil(max_h).div_ceil(8);
            c.height_in_blocks = (height * c.v).div_ceil(max_v).div_ceil(8);
            c.blocks_w = mcus_x * c.h;
            c.coefs = vec![0; c.blocks_w * mcus_y * c.v * 64];
        }
        Ok(Frame { width, height, progressive, components, max_h, max_v, mcus_x, mcus_y, color: ColorSpace::Grey })
    }

    fn parse_scan(&mut self, s: &[u8], quant: &[Option<[u16; 64]>; 4]) -> Result<Scan, String> {
        let n = *s.first().ok_or("bad JPEG scan header")? as usize;
        if !(1..=4).contains(&n) || s.len() < 1 + 2 * n + 3 {
            return Err("bad JPEG scan header".into());
        }
        let mut scan = Scan { components: vec![], dc_slots: vec![], ac_slots: vec![], ss: 0, se: 0, ah: 0, al: 0 };
        for c in s[1..1 + 2 * n].chunks_exact(2) {
            let index = self
                .components
                .iter()
                .position(|k| k.id == c[0])
                .ok_or_else(|| format!("JPEG scan names component {} that the frame lacks", c[0]))?;
            scan.components.push(index);
            scan.dc_slots.push((c[1] >> 4) as usize);
            scan.ac_slots.push((c[1] & 15) as usize);
        }
        let t = &s[1 + 2 * n..];
        (scan.ss, scan.se, scan.ah, scan.al) = (t[0] as usize, t[1] as usize, (t[2] >> 4) as u32, (t[2] & 15) as u32);
        if n > 1 && scan.components.iter().map(|&i| self.components[i].h * self.components[i].v).sum::<usize>() > 10 {
            return Err("bad JPEG: more than 10 blocks in an MCU".into());
        }
        if self.progressive {
            let dc = scan.ss == 0;
            let bad = (dc && scan.se != 0)
                || (!dc && (scan.ss > scan.se || scan.se > 63 || n != 1))
                || (scan.ah != 0 && scan.al + 1 != scan.ah)
                || scan.al > 13;
            if bad {
                return Err("bad JPEG progressive scan parameters".into());
            }
        }
        for &i in &scan.components {
            let c = &mut self.components[i];
            if c.quant.is_none() {
                c.quant = Some(
                    quant[c.quant_slot]
                        .ok_or_else(|| format!("JPEG quantisation table {} is not defined", c.quant_slot))?,
                );
            }
        }
        Ok(scan)
    }

    /// libjpeg-turbo's `default_decompress_parms`.
    fn choose_color(&mut self, jfif: bool, adobe: Option<u8>) {
        self.color = match self.components.len() {
            1 => ColorSpace::Grey,
            3 => {
                let ids: Vec<u8> = self.components.iter().map(|c| c.id).collect();
                if jfif {
                    ColorSpace::YCbCr
                } else if let Some(transform) = adobe {
                    if transform == 0 {
                        ColorSpace::Rgb
                    } else {
                        ColorSpace::YCbCr
                    }
                } else if ids == b"RGB" {
                    ColorSpace::Rgb
                } else {
                    ColorSpace::YCbCr
                }
            }
            _ => match adobe {
                Some(0) | None => ColorSpace::Cmyk,
                Some(_) => ColorSpace::Ycck,
            },
        };
    }
}

/// Parses the whole file and decodes every scan into the frame's coefficients.
pub(super) fn decode(data: &[u8]) -> Result<Frame, String> {
    if !data.starts_with(&[0xFF, 0xD8, 0xFF]) {
        return Err("not a JPEG file (no start-of-image marker)".into());
    }
    let mut pos = 2;
    let mut tables = Tables::default();
    let mut frame: Option<Frame> = None;
    let (mut jfif, mut adobe) = (false, None);
    let mut pending: Option<u8> = None;
    let mut scans = 0;
    // A sequential file whose first scan holds every component is output as soon as that scan
    // is decoded: libjpeg-turbo then tolerates the end of the file, but not a second scan.
    let mut complete = false;
    loop {
        let marker = match pending.take().or_else(|| next_marker(data, &mut pos)) {
            Some(m) => m,
            None if complete => break,
            None => return Err(TRUNCATED.into()),
        };
        match marker {
            0xC0..=0xC2 => {
                if frame.is_some() {
                    return Err("JPEG with two frame headers".into());
                }
                frame = Some(Frame::parse(segment(data, &mut pos)?, marker == 0xC2)?);
            }
            0xC3 | 0xC5..=0xC7 | 0xC9..=0xCB | 0xCD..=0xCF => {
                return Err(format!(
                    "{} JPEG (SOF{}) is not supported; Pillow-compatible decoding covers baseline and \
                    progressive Huffman JPEG",
                    sof_kind(marker),
                    marker - 0xC0
                ));
            }
            0xC4 => tables.read_huffman(segment(data, &mut pos)?)?,
            0xDB => tables.read_quant(segment(data, &mut pos)?)?,
            0xDD => {
                let s = segment(data, &mut pos)?;
                tables.restart_interval =
                    if s.len() >= 2 { u16_at(s, 0) } else { return Err("bad JPEG restart interval".into()) };
            }
            0xDA => {
                let f = frame.as_mut().ok_or("JPEG scan before the frame header")?;
                if complete {
                    return Err("bad JPEG: a second scan after a complete single-scan image".into());
                }
                let header = segment(data, &mut pos)?;
                let scan = f.parse_scan(header, &tables.quant)?;
                if scans == 0 && !f.progressive {
                    tables.fill_standard_huffman();
                }
                let scan_tables = ScanTables {
                    dc: scan.dc_slots.iter().map(|&i| tables.dc.get(i).and_then(Option::as_ref)).collect(),
                    ac: scan.ac_slots.iter().map(|&i| tables.ac.get(i).and_then(Option::as_ref)).collect(),
                };
                let (end, marker) = decode_scan(f, &scan, &scan_tables, tables.restart_interval, data, pos)?;
                (pos, pending) = (end, marker);
                scans += 1;
                complete = !f.progressive && scans == 1 && scan.components.len() == f.components.len();
            }
            0xD9 => break,
            0xD8 => return Err("bad JPEG: a second start-of-image marker".into()),
            0xD0..=0xD7 | 0x01 => {}
            0xE0 => {
                let s = segment(data, &mut pos)?;
                jfif |= s.len() >= 14 && s.starts_with(b"JFIF\0");
            }
            0xEE => {
                let s = segment(data, &mut pos)?;
                if s.len() >= 12 && s.starts_with(b"Adobe") {
                    adobe = Some(s[11]);
                }
            }
            0xE1..=0xED | 0xEF..=0xFE | 0xCC | 0xDC => {
                segment(data, &mut pos)?;
            }
            other => return Err(format!("bad JPEG: unknown marker 0xFF{other:02X}")),
        }
    }
    let mut frame = frame.ok_or("JPEG without a frame header")?;
    if scans == 0 {
        return Err("JPEG without image data (no scan)".into());
    }
    frame.choose_color(jfif, adobe);
    Ok(frame)
}
