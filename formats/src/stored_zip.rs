//! The stored (uncompressed) entries of a zip archive, found through its central directory, zip64
//! records included: how `torch.save` writes its checkpoints (`crate::torch_pth`).

use std::collections::HashMap;
use std::ops::Range;

/// Parse errors before the file's path is attached.
type Parsed<T> = std::result::Result<T, String>;

/// The stored entries of a zip archive by name, as byte ranges of `data`, found through its central directory.
pub(crate) fn zip_entries(data: &[u8]) -> Parsed<HashMap<String, Range<usize>>> {
    let truncated = || "a zip record runs past the end of the file (truncated?)".to_string();
    let field = |at: usize, n: usize| le(data, at, n).ok_or_else(truncated);
    // The end-of-central-directory record ends the file, but for a comment of up to 64 KiB.
    let last = data.len().saturating_sub(22);
    let eocd = (last.saturating_sub(0xffff)..=last).rev().find(|&at| le(data, at, 4) == Some(0x0605_4b50));
    let eocd = eocd.ok_or("no zip end-of-central-directory record (truncated?)")?;
    let (mut count, mut cd_size, mut cd_at) = (field(eocd + 10, 2)?, field(eocd + 12, 4)?, field(eocd + 16, 4)?);
    // Torch always writes the zip64 records; files past 4 GiB need them.
    if eocd >= 20 && le(data, eocd - 20, 4) == Some(0x0706_4b50) {
        let at = field(eocd - 12, 8)?;
        if le(data, at, 4) != Some(0x0606_4b50) {
            return Err("the zip64 locator points at no zip64 end-of-central-directory record".into());
        }
        (count, cd_size, cd_at) = (field(at + 32, 8)?, field(at + 40, 8)?, field(at + 48, 8)?);
    }
    let cd_end = cd_at.checked_add(cd_size).filter(|&end| end <= data.len()).ok_or_else(truncated)?;
    let mut entries = HashMap::new();
    let mut at = cd_at;
    for _ in 0..count {
        if at + 46 > cd_end || field(at, 4)? != 0x0201_4b50 {
            return Err("the zip central directory is malformed".into());
        }
        let (flags, method) = (field(at + 8, 2)?, field(at + 10, 2)?);
        let (name_len, extra_len, comment_len) = (field(at + 28, 2)?, field(at + 30, 2)?, field(at + 32, 2)?);
        let name = String::from_utf8_lossy(data.get(at + 46..at + 46 + name_len).ok_or_else(truncated)?).into_owned();
        let extra = data.get(at + 46 + name_len..at + 46 + name_len + extra_len).ok_or_else(truncated)?;
        // Uncompressed size, compressed size, local header offset; saturated ones are in the zip64
        // extra field, in this order.
        let mut sizes = [field(at + 24, 4)?, field(at + 20, 4)?, field(at + 42, 4)?];
        if let Some(mut zip64) = extra_field(extra, 1) {
            for v in sizes.iter_mut().filter(|v| **v == 0xffff_ffff) {
                *v = le(zip64, 0, 8).ok_or("a zip64 extra field is too short")?;
                zip64 = &zip64[8..];
            }
        }
        let [uncompressed, size, local] = sizes;
        if method != 0 || flags & 1 != 0 {
            return Err(format!(
                "zip entry `{name}` is compressed or encrypted (method {method}); torch.save stores entries, so \
                    re-save it with torch"
            ));
        }
        if size != uncompressed {
            return Err(format!("zip entry `{name}` is stored with {size} bytes for {uncompressed}"));
        }
        // The data follows the local header, whose own name and extra field (torch pads it to align
        // the data) set where.
        if field(local, 4)? != 0x0403_4b50 {
            return Err(format!("zip entry `{name}` has no local header"));
        }
        let start = local + 30 + field(local + 26, 2)? + field(local + 28, 2)?;
        let end = start
            .checked_add(size)
            .filter(|&end| end <= data.len())
            .ok_or_else(|| format!("zip entry `{name}` runs past the end of the file (truncated?)"))?;
        entries.insert(name, start..end);
        at += 46 + name_len + extra_len + comment_len;
    }
    Ok(entries)
}

/// The body of the first field with tag `id` in a zip extra field.
fn extra_field(mut extra: &[u8], id: usize) -> Option<&[u8]> {
    while extra.len() >= 4 {
        let (tag, len) = (le(extra, 0, 2)?, le(extra, 2, 2)?);
        let body = extra.get(4..4 + len)?;
        if tag == id {
            return Some(body);
        }
        extra = &extra[4 + len..];
    }
    None
}

/// A little-endian unsigned field of `n` bytes at `at`, if it lies inside `data`.
pub(crate) fn le(data: &[u8], at: usize, n: usize) -> Option<usize> {
    let bytes = data.get(at..at.checked_add(n)?)?;
    usize::try_from(bytes.iter().rev().fold(0u64, |v, &b| v << 8 | b as u64)).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A one-entry archive laid out by hand as PKWARE's APPNOTE lays it out, the entry's sizes
    /// and local header offset saturated (0xffffffff) in the central directory and given in its
    /// zip64 extra field (tag 1), after a field of another tag: as a torch.save past 4 GiB writes it.
    #[test]
    fn saturated_sizes_are_read_from_the_zip64_extra_field() {
        let (name, body) = (b"archive/data/0", b"hello");
        let u16s = |v: usize| (v as u16).to_le_bytes();
        let mut zip = Vec::new();
        zip.extend(0x0403_4b50u32.to_le_bytes());
        zip.extend([0; 22]); // versions, flags, method 0 (stored), times, CRC, sizes
        zip.extend(u16s(name.len()));
        zip.extend(u16s(0));
        zip.extend(name);
        zip.extend(body);
        let cd_at = zip.len();
        let mut extra = vec![0x55, 0x54, 1, 0, 0]; // tag 0x5455 (times), 1 byte
        extra.extend([1, 0, 24, 0]); // tag 1 (zip64), 24 bytes: uncompressed, compressed, offset
        for v in [body.len(), body.len(), 0] {
            extra.extend((v as u64).to_le_bytes());
        }
        zip.extend(0x0201_4b50u32.to_le_bytes());
        zip.extend([0; 16]); // versions, flags, method 0, times, CRC
        zip.extend([0xff; 8]); // compressed and uncompressed sizes, saturated
        zip.extend(u16s(name.len()));
        zip.extend(u16s(extra.len()));
        zip.extend([0; 10]); // comment length, disk, attributes
        zip.extend([0xff; 4]); // local header offset, saturated
        zip.extend(name);
        zip.extend(&extra);
        let cd_size = zip.len() - cd_at;
        zip.extend(0x0605_4b50u32.to_le_bytes());
        zip.extend([0, 0, 0, 0, 1, 0, 1, 0]); // disks, entries here and in all
        zip.extend((cd_size as u32).to_le_bytes());
        zip.extend((cd_at as u32).to_le_bytes());
        zip.extend([0, 0]);
        let entries = zip_entries(&zip).unwrap();
        let start = 30 + name.len();
        assert_eq!(entries["archive/data/0"], start..start + body.len());
        assert_eq!(&zip[entries["archive/data/0"].clone()], body);
    }
}
