//! JPEG decoding held to Pillow byte for byte, on the corpus of `tools/make_jpeg_fixtures.py`
//! (files from Pillow, cjpeg and ImageMagick; Pillow 13.0.0 with libjpeg-turbo 3.2.0 decoded
//! them). Files Pillow refuses are refused too; the one kind Pillow reads and vkdiff does not
//! (arithmetic coding) is refused with a reason. One case is known not to be exact: a progressive
//! file that ends before its refinement scans, which libjpeg-turbo smooths across blocks.

use std::path::{Path, PathBuf};

use serde_json::Value;
use vkdiff_formats::image::read_image;

fn dir() -> PathBuf {
    vkdiff_testkit::fixture("jpeg")
}

/// Kinds of JPEG Pillow reads and vkdiff refuses, with what the refusal must say.
const REFUSED: [(&str, &str); 1] = [("cjpeg_arithmetic", "arithmetic-coded")];

/// Files decoded without libjpeg-turbo's inter-block smoothing of unrefined progressive
/// coefficients, with the largest difference allowed (measured: 17).
const NOT_SMOOTHED: [(&str, u8); 1] = [("progressive_first_scans_only", 24)];

#[test]
fn jpeg_decodes_as_pillow_does() {
    let index: Value = serde_json::from_str(&std::fs::read_to_string(dir().join("index.json")).unwrap()).unwrap();
    let cases = index["cases"].as_object().unwrap();
    assert!(cases.len() >= 25, "the corpus is there");
    let mut failures = Vec::new();
    for (name, case) in cases {
        let got = read_image(&dir().join(format!("{name}.jpg")));
        if let Some(why) = case["pillow_error"].as_str() {
            if let Ok(img) = got {
                failures.push(format!("{name}: decoded {}x{}, Pillow refused it ({why})", img.width, img.height));
            }
            continue;
        }
        if let Some((_, reason)) = REFUSED.iter().find(|(n, _)| n == name) {
            match got {
                Err(e) if e.to_string().contains(reason) => {}
                other => failures.push(format!(
                    "{name}: expected a refusal naming {reason:?}, got {:?}",
                    other.map(|i| (i.width, i.height))
                )),
            }
            continue;
        }
        let want = read_image(&dir().join(format!("{name}.png"))).unwrap();
        let got = match got {
            Ok(img) => img,
            Err(e) => {
                failures.push(format!("{name}: {e}"));
                continue;
            }
        };
        if (got.width, got.height) != (want.width, want.height) {
            failures.push(format!("{name}: {}x{}, Pillow {}x{}", got.width, got.height, want.width, want.height));
            continue;
        }
        let worst = got.pixels.iter().zip(&want.pixels).map(|(a, b)| a.abs_diff(*b)).max().unwrap();
        let differ = got.pixels.iter().zip(&want.pixels).filter(|(a, b)| a != b).count();
        println!(
            "{name:<32} {}x{} ({}): largest difference {worst}",
            got.width,
            got.height,
            case["pil_mode"].as_str().unwrap()
        );
        if let Some((_, bound)) = NOT_SMOOTHED.iter().find(|(n, _)| n == name) {
            if worst > *bound {
                failures.push(format!(
                    "{name}: differs from Pillow by {worst}, more than the {bound} its missing smoothing explains"
                ));
            }
        } else if worst > 0 {
            failures
                .push(format!("{name}: {differ} of {} bytes differ from Pillow, by up to {worst}", got.pixels.len()));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn malformed_jpeg_is_an_error_not_a_panic() {
    let good = std::fs::read(dir().join("pil_progressive_444_optimize.jpg")).unwrap();
    let path = Path::new("cut.jpg");
    // Every truncation, and a damaged byte at every position: an image or an error, never a panic.
    for cut in 0..good.len() {
        let _ = vkdiff_formats::image::decode_image(&good[..cut], path);
    }
    for at in 0..good.len() {
        for flip in [0x01, 0x80, 0xFF] {
            let mut bad = good.clone();
            bad[at] ^= flip;
            let _ = vkdiff_formats::image::decode_image(&bad, path);
        }
    }
}

/// Pillow opens no image past twice its `MAX_IMAGE_PIXELS` (89,478,485): a decompression bomb.
/// vkdiff refuses the same frames, from their header alone, before reading any data.
#[test]
fn a_frame_past_pillows_pixel_limit_is_refused_from_its_header() {
    // SOI, then a baseline frame header of side × side with one component, then EOI.
    let frame = |side: u16| {
        let [hi, lo] = side.to_be_bytes();
        vec![0xFF, 0xD8, 0xFF, 0xC0, 0, 11, 8, hi, lo, hi, lo, 1, 1, 0x11, 0, 0xFF, 0xD9]
    };
    let why =
        |side: u16| vkdiff_formats::image::decode_image(&frame(side), Path::new("big.jpg")).unwrap_err().to_string();
    // 13,378² = 178,970,884 pixels: past 178,956,970; 13,377² = 178,944,129 is not (Pillow 13.0.0
    // raises DecompressionBombError for the first, OSError for the second: it has no scan).
    assert!(why(13_378).contains("13378x13378 JPEG: more pixels than Pillow opens (178956970)"), "{}", why(13_378));
    assert!(!why(13_377).contains("more pixels"), "{}", why(13_377));
}
