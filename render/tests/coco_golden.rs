//! Our RLE against pycocotools: the fixture holds label images and what pycocotools made of them
//! (written by `tools/coco_golden.py fixture`; versions recorded inside).

use serde_json::Value;
use vkdiff_render::rle::{PixelBox, Rle};

fn fixture() -> Value {
    let text =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/coco_rle_golden.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

#[test]
fn encoding_area_bbox_and_decoding_match_pycocotools() {
    let doc = fixture();
    let cases = doc["cases"].as_array().unwrap();
    assert!(cases.len() >= 6);
    let mut checked = 0;
    for case in cases {
        let (h, w) = (case["height"].as_u64().unwrap() as u32, case["width"].as_u64().unwrap() as u32);
        let labels: Vec<u8> = case["rows"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|row| row.as_str().unwrap().bytes())
            .map(|c| if c == b'.' { 0 } else { c - b'a' + 1 })
            .collect();
        assert_eq!(labels.len(), (w * h) as usize);
        let everything = PixelBox { x0: 0, y0: 0, x1: w - 1, y1: h - 1 };
        for ann in case["annotations"].as_array().unwrap() {
            let label = ann["label"].as_u64().unwrap() as u8;
            let name = format!("{} label {label}", case["name"]);
            let ours = Rle::from_labels(&labels, w, h, label, everything);
            let golden = ann["counts"].as_str().unwrap();
            assert_eq!(ours.to_coco_string(), golden, "{name}: counts string");
            assert_eq!(ours.area(), ann["area"].as_u64().unwrap(), "{name}: area");
            let bbox: Vec<u64> = ours.bbox().unwrap().to_xywh().iter().map(|&v| v as u64).collect();
            let golden_bbox: Vec<u64> = ann["bbox"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap()).collect();
            assert_eq!(bbox, golden_bbox, "{name}: bbox");
            // Decoding pycocotools' string gives back exactly the label's pixels.
            let decoded = Rle::from_coco_string(golden, h, w).unwrap();
            assert_eq!(decoded, ours, "{name}: decoded counts");
            let mask: Vec<bool> = labels.iter().map(|&l| l == label).collect();
            assert_eq!(decoded.to_mask(), mask, "{name}: decoded mask");
            // Reading only the label's bounding box gives the same encoding.
            assert_eq!(Rle::from_labels(&labels, w, h, label, ours.bbox().unwrap()), ours, "{name}: bbox scan");
            checked += 1;
        }
    }
    assert!(checked > 25, "only {checked} masks checked");
}
