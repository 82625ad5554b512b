//! safetensors as the format's README lays it out (an 8-byte little-endian header length, a JSON
//! header of dtype, shape and data offsets, the data 8-byte aligned): files written by hand read,
//! files too short for their header refused, and vkdiff's own files read back.

use std::collections::BTreeMap;
use std::path::Path;
use vkdiff_formats::{SafeTensors, SourceDtype};

/// A file of `header` (JSON) and `data`, as the format lays them out.
fn file(header: &str, data: &[u8]) -> Vec<u8> {
    let mut bytes = (header.len() as u64).to_le_bytes().to_vec();
    bytes.extend(header.as_bytes());
    bytes.extend(data);
    bytes
}

#[test]
fn half_floats_written_by_hand_read_as_their_values() {
    let header = r#"{"h":{"dtype":"F16","shape":[2],"data_offsets":[0,4]},
        "b":{"dtype":"BF16","shape":[1],"data_offsets":[4,6]},"__metadata__":{"format":"pt"}}"#;
    // 1.0 and -2.0 in IEEE half (sign, 5-bit exponent biased by 15), 1.0 in bfloat16 (f32's top half).
    let data = [0x00, 0x3c, 0x00, 0xc0, 0x80, 0x3f];
    let st = SafeTensors::from_bytes(Path::new("hand.safetensors"), file(header, &data)).unwrap();
    assert_eq!(st.entries["h"].dtype, SourceDtype::F16);
    assert_eq!(st.values("h").unwrap(), (vec![2], vec![1.0, -2.0]));
    assert_eq!(st.values("b").unwrap(), (vec![1], vec![1.0]));
    assert_eq!(st.metadata["format"], "pt");
}

#[test]
fn files_too_short_for_their_header_are_refused() {
    let header = r#"{"x":{"dtype":"F32","shape":[1],"data_offsets":[0,4]}}"#;
    let whole = file(header, &1f32.to_le_bytes());
    assert!(SafeTensors::from_bytes(Path::new("whole"), whole.clone()).is_ok());
    for cut in [0, 7, 8, 9, whole.len() - 5] {
        let err = SafeTensors::from_bytes(Path::new("cut"), whole[..cut].to_vec()).err();
        assert!(err.is_some(), "{cut} of {} bytes read", whole.len());
    }
}

#[test]
fn written_files_read_back_with_their_data_aligned() {
    let path = std::env::temp_dir().join(format!("vkdiff-safetensors-{}.safetensors", std::process::id()));
    let (a, b) = ([1.5f32, -2.0], [0.25f32, 3.0, -7.5]);
    let metadata = BTreeMap::from([("by".to_string(), "vkdiff".to_string())]);
    vkdiff_formats::write_safetensors_f32(&path, &[("a", &[2], &a), ("b", &[3, 1], &b)], &metadata).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    std::fs::remove_file(&path).unwrap();
    let header = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    assert_eq!((8 + header) % 8, 0, "the data starts 8-byte aligned");
    let st = SafeTensors::from_bytes(&path, bytes).unwrap();
    assert_eq!(st.values("a").unwrap(), (vec![2], a.to_vec()));
    assert_eq!(st.values("b").unwrap(), (vec![3, 1], b.to_vec()));
    assert_eq!(st.metadata, metadata);
}
