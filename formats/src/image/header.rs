//! Image sizes read from their headers alone, for checking a folder of scenes before any pixel is
//! decoded: each scene's pixels are then read once, when its images are made.

use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::Path;

use crate::{Error, Result};

fn open(path: &Path) -> Result<std::fs::File> {
    std::fs::File::open(path).map_err(|source| Error::Io { path: path.to_path_buf(), source })
}

fn format_error(path: &Path) -> impl Fn(String) -> Error + '_ {
    move |why| Error::Format { path: path.to_path_buf(), why }
}

/// (width, height) of a PNG or JPEG file (told apart by their first bytes, as [`super::read_image`]
/// tells them), from its header.
pub fn image_size(path: &Path) -> Result<(usize, usize)> {
    let fail = format_error(path);
    let io = |source| Error::Io { path: path.to_path_buf(), source };
    let mut reader = BufReader::new(open(path)?);
    let mut magic = [0u8; 8];
    let got = read_up_to(&mut reader, &mut magic).map_err(io)?;
    reader.seek(SeekFrom::Start(0)).map_err(io)?;
    if magic.starts_with(b"\x89PNG\r\n\x1a\n") {
        let reader = png::Decoder::new(reader).read_info().map_err(|e| png_error(path, e))?;
        Ok((reader.info().width as usize, reader.info().height as usize))
    } else if magic.starts_with(&[0xff, 0xd8]) {
        jpeg_size(reader).map_err(fail)
    } else if got == 0 {
        Err(fail("empty file".into()))
    } else {
        Err(fail("not a PNG or JPEG file (the formats read as images)".into()))
    }
}

/// A PNG header that cannot be read (an I/O error, as a file error) or parsed.
fn png_error(path: &Path, e: png::DecodingError) -> Error {
    match e {
        png::DecodingError::IoError(source) => Error::Io { path: path.to_path_buf(), source },
        e => Error::Format { path: path.to_path_buf(), why: format!("bad PNG: {e}") },
    }
}

/// Fills `buf` as far as the file goes; the bytes read.
fn read_up_to(reader: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut got = 0;
    while got < buf.len() {
        match reader.read(&mut buf[got..])? {
            0 => break,
            n => got += n,
        }
    }
    Ok(got)
}

/// A JPEG's size from its frame header (SOF0–SOF15, less DHT, JPG and DAC, which share the range),
/// walking the marker segments before it.
fn jpeg_size(mut bytes: impl Read) -> std::result::Result<(usize, usize), String> {
    let mut byte = || -> std::result::Result<u8, String> {
        let mut b = [0u8; 1];
        bytes.read_exact(&mut b).map_err(|_| "bad JPEG: ends before its frame header".to_string())?;
        Ok(b[0])
    };
    // SOI, checked by the caller.
    byte()?;
    byte()?;
    loop {
        if byte()? != 0xff {
            return Err("bad JPEG: a segment does not start with a marker".into());
        }
        let mut marker = byte()?;
        while marker == 0xff {
            marker = byte()?;
        }
        if matches!(marker, 0x01 | 0xd0..=0xd7) {
            continue;
        }
        let length = u16::from_be_bytes([byte()?, byte()?]) as usize;
        if length < 2 {
            return Err(format!("bad JPEG: marker {marker:#04x} has length {length}"));
        }
        if (0xc0..=0xcf).contains(&marker) && !matches!(marker, 0xc4 | 0xc8 | 0xcc) {
            let _precision = byte()?;
            let height = u16::from_be_bytes([byte()?, byte()?]) as usize;
            let width = u16::from_be_bytes([byte()?, byte()?]) as usize;
            return Ok((width, height));
        }
        for _ in 2..length {
            byte()?;
        }
    }
}

/// (width, height, bits) of an 8- or 16-bit grey PNG, from its header; any other colour type is
/// refused as [`super::read_grey_png`] refuses it.
pub fn grey_png_size(path: &Path) -> Result<(usize, usize, u8)> {
    let fail = format_error(path);
    let reader = png::Decoder::new(BufReader::new(open(path)?)).read_info().map_err(|e| png_error(path, e))?;
    let info = reader.info();
    let bits = super::grey::grey_bits(info.color_type, info.bit_depth).map_err(fail)?;
    Ok((info.width as usize, info.height as usize, bits))
}

/// (width, height) of the depth channel [`super::read_depth_exr`] would read, from the file's
/// headers.
pub fn depth_exr_size(path: &Path) -> Result<(usize, usize)> {
    let (names, sizes) = exr_channels(path)?;
    Ok(sizes[super::depth_exr::pick(&names).map_err(format_error(path))?])
}

/// (width, height) of the normals [`super::read_normals_exr`] would read, from the file's headers.
pub fn normals_exr_size(path: &Path) -> Result<(usize, usize)> {
    let (names, sizes) = exr_channels(path)?;
    Ok(sizes[super::depth_exr::pick_normals(&names, &sizes).map_err(format_error(path))?[0]])
}

/// Each channel's name, and its part's (width, height).
type Channels = (Vec<String>, Vec<(usize, usize)>);

/// Every channel's name (`<part>.<channel>` in named parts) and its part's (width, height), from
/// an EXR file's headers.
fn exr_channels(path: &Path) -> Result<Channels> {
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|e| match e {
        exr::error::Error::Io(source) => Error::Io { path: path.to_path_buf(), source },
        e => format_error(path)(format!("bad OpenEXR file: {e}")),
    })?;
    let mut names = Vec::new();
    let mut sizes = Vec::new();
    for header in &meta.headers {
        let prefix = header.own_attributes.layer_name.as_ref().map(|n| format!("{n}."));
        for channel in &header.channels.list {
            names.push(format!("{}{}", prefix.as_deref().unwrap_or(""), channel.name));
            sizes.push((header.layer_size.0, header.layer_size.1));
        }
    }
    Ok((names, sizes))
}
