//! Image inputs against what Pillow, torch/torchvision, diffusers and transformers make of the
//! same files (tests/fixtures/images, written by tools/make_image_fixtures.py).

use std::path::{Path, PathBuf};

use serde_json::Value;
use vkdiff_pipeline::images::{
    center_crop, control_tensor, depth_control_image, load_control_image, read_depth_exr, read_image, resize_pil,
    resize_torch, ClipPreprocess, ControlDepth, Filter,
};
use vkdiff_pipeline::RgbImage;
use vkdiff_render::control::control_image;

fn dir() -> PathBuf {
    vkdiff_testkit::fixture("images")
}

struct Fixtures {
    index: Value,
    expected: Vec<u8>,
}

impl Fixtures {
    fn load() -> Self {
        let index = serde_json::from_str(&std::fs::read_to_string(dir().join("index.json")).unwrap()).unwrap();
        Fixtures { index, expected: std::fs::read(dir().join("expected.bin")).unwrap() }
    }
    fn entries(&self, kind: &str) -> &Vec<Value> {
        self.index[kind].as_array().unwrap()
    }
    fn bytes(&self, range: &Value) -> &[u8] {
        let (a, b) = (range[0].as_u64().unwrap() as usize, range[1].as_u64().unwrap() as usize);
        &self.expected[a..b]
    }
    fn floats(&self, range: &Value) -> Vec<f32> {
        self.bytes(range).chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().unwrap())).collect()
    }
}

fn usize_of(v: &Value) -> usize {
    v.as_u64().unwrap() as usize
}

fn source(entry: &Value) -> RgbImage {
    read_image(&dir().join(entry["file"].as_str().unwrap())).unwrap()
}

fn filter(name: &str) -> Filter {
    match name {
        "bilinear" => Filter::Bilinear,
        "bicubic" => Filter::Bicubic,
        "lanczos" => Filter::Lanczos,
        _ => panic!("{name}"),
    }
}

#[test]
fn png_files_read_as_pil_converts_them_to_rgb() {
    let f = Fixtures::load();
    assert!(f.entries("png").len() >= 17);
    for e in f.entries("png") {
        let img = source(e);
        assert_eq!((img.width, img.height), (usize_of(&e["width"]), usize_of(&e["height"])), "{e}");
        assert_eq!(img.pixels, f.bytes(&e["rgb"]), "{} (PIL mode {})", e["file"], e["pil_mode"]);
    }
}

#[test]
fn jpeg_decodes_as_pillow_does() {
    // The whole JPEG corpus is tests/jpeg.rs'; this is the photo the resize fixtures start from.
    let f = Fixtures::load();
    let e = &f.entries("jpeg")[0];
    let img = source(e);
    assert_eq!((img.width, img.height), (21, 13));
    assert_eq!(img.pixels, f.bytes(&e["rgb"]), "{} against Pillow (libjpeg-turbo)", e["file"]);
}

fn check_resizes(kind: &str, resize: fn(&RgbImage, usize, usize, Filter) -> RgbImage) {
    let f = Fixtures::load();
    let mut failures = Vec::new();
    for e in f.entries(kind) {
        let (w, h) = (usize_of(&e["width"]), usize_of(&e["height"]));
        let out = resize(&source(e), w, h, filter(e["filter"].as_str().unwrap()));
        assert_eq!((out.width, out.height), (w, h));
        let want = f.bytes(&e["rgb"]);
        let differ = out.pixels.iter().zip(want).filter(|(a, b)| a != b).count();
        if differ > 0 {
            failures.push(format!("{} -> {w}x{h} {}: {differ} bytes differ", e["file"], e["filter"]));
        }
    }
    assert!(f.entries(kind).len() > 30);
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn pil_resize_is_bit_exact() {
    check_resizes("pil_resize", resize_pil);
}

#[test]
fn torch_uint8_antialiased_resize_is_bit_exact() {
    check_resizes("torch_resize", resize_torch);
}

#[test]
fn the_two_resizes_really_differ() {
    // Guards the tests above against both references being the same function.
    let img = source(&serde_json::json!({"file": "src_37x29.png"}));
    assert_ne!(resize_pil(&img, 19, 15, Filter::Bicubic).pixels, resize_torch(&img, 19, 15, Filter::Bicubic).pixels);
}

#[test]
fn control_tensor_matches_diffusers() {
    let f = Fixtures::load();
    for e in f.entries("control") {
        let (values, shape) = control_tensor(&source(e), usize_of(&e["width"]), usize_of(&e["height"]));
        let want_shape: Vec<usize> = e["shape"].as_array().unwrap().iter().map(usize_of).collect();
        assert_eq!(shape.to_vec(), want_shape, "{e}");
        assert_eq!(values, f.floats(&e["values"]), "{e}");
    }
}

#[test]
fn clip_preprocessing_matches_transformers() {
    let f = Fixtures::load();
    for e in f.entries("clip") {
        let config = e["config"].as_str().unwrap();
        let p = if config == "default56" {
            ClipPreprocess::square(56)
        } else {
            ClipPreprocess::from_file(&dir().join(config).join("preprocessor_config.json")).unwrap()
        };
        let (values, shape) = p.apply(&source(e));
        let want_shape: Vec<usize> = e["shape"].as_array().unwrap().iter().map(usize_of).collect();
        assert_eq!(shape.to_vec(), want_shape, "{e}");
        let want = f.floats(&e["values"]);
        let worst = values.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        assert!(worst <= 1e-5, "{config} {}: max abs difference {worst}", e["file"]);
    }
}

#[test]
fn clip_config_rejects_what_it_cannot_do() {
    let err = ClipPreprocess::from_json(r#"{"resample": 1}"#).unwrap_err();
    assert!(err.contains("resample 1"), "{err}");
    let err = ClipPreprocess::from_json(r#"{"image_processor_type": "SiglipImageProcessor"}"#).unwrap_err();
    assert!(err.contains("SiglipImageProcessor"), "{err}");
    let p =
        ClipPreprocess::from_json(r#"{"size": {"height": 10, "width": 12}, "crop_size": 8, "whatever": [1]}"#).unwrap();
    assert_eq!(p.resized_size(100, 50), (10, 12));
    assert_eq!(p.crop_size, (8, 8));
    assert_eq!(ClipPreprocess::from_json("{}").unwrap(), ClipPreprocess::default());
    // transformers truncates the longer edge: 224 * 300 / 200 = 336, 224 * 301 / 199 = 338.8.
    assert_eq!(ClipPreprocess::square(224).resized_size(301, 199), (338, 224));
    assert_eq!(ClipPreprocess::square(224).resized_size(199, 301), (224, 338));
}

#[test]
fn center_crop_offsets_round_down_and_padding_is_zero() {
    let img = RgbImage { width: 3, height: 1, pixels: vec![1, 1, 1, 2, 2, 2, 3, 3, 3] };
    assert_eq!(center_crop(&img, 1, 2).pixels, vec![1, 1, 1, 2, 2, 2]);
    let padded = center_crop(&img, 2, 4);
    assert_eq!(padded.pixels, vec![1, 1, 1, 2, 2, 2, 3, 3, 3, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]);
}

#[test]
fn exr_depth_from_openexr_files_becomes_the_control_image() {
    let f = Fixtures::load();
    let mut checked = 0;
    for e in f.entries("exr") {
        let path = dir().join(e["file"].as_str().unwrap());
        let depth = f.floats(&e["depth"]);
        match e["file"].as_str().unwrap() {
            "no_depth.exr" => {
                let err = read_depth_exr(&path).unwrap_err().to_string();
                assert!(err.contains("no_depth.exr") && err.contains("channels: A, Y"), "{err}");
            }
            "two_layers.exr" => {
                let err = read_depth_exr(&path).unwrap_err().to_string();
                assert!(err.contains("A.Depth.Z, B.Depth.Z"), "{err}");
            }
            name => {
                let (values, w, h) = read_depth_exr(&path).unwrap();
                assert_eq!((w, h), (usize_of(&e["width"]), usize_of(&e["height"])));
                assert_eq!(
                    values.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                    depth.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                    "{name}"
                );
                for mode in [ControlDepth::Inverse, ControlDepth::Linear] {
                    let img = depth_control_image(&path, mode).unwrap();
                    assert_eq!(img.pixels, control_image(&depth, mode), "{name} {mode:?}");
                }
                let img = load_control_image(&path, ControlDepth::Inverse).unwrap();
                assert_eq!(&img.pixels[0..3], &[0, 0, 0], "infinite depth is black");
                assert!(img.pixels.contains(&255));
                checked += 1;
            }
        }
    }
    assert_eq!(checked, 4);
}

#[test]
fn exr_from_our_own_writer_is_read() {
    let depth: Vec<f32> = (0..6 * 20).map(|i| 1.0 + (i % 7) as f32 * 0.1).collect();
    let path = std::env::temp_dir().join(format!("vkdiff-images-{}.exr", std::process::id()));
    std::fs::write(&path, vkdiff_render::exr::encode_single_channel(6, 20, "Z", &depth)).unwrap();
    let img = load_control_image(&path, ControlDepth::Linear).unwrap();
    std::fs::remove_file(&path).unwrap();
    assert_eq!((img.width, img.height), (6, 20));
    assert_eq!(img.pixels, control_image(&depth, ControlDepth::Linear));
}

#[test]
fn non_exr_control_images_are_used_as_they_are() {
    let path = dir().join("src_37x29.png");
    let img = load_control_image(&path, ControlDepth::Inverse).unwrap();
    assert_eq!(img.pixels, read_image(&path).unwrap().pixels);
}

#[test]
fn errors_name_the_file_and_the_problem() {
    let err = read_image(Path::new("/nonexistent/x.png")).unwrap_err().to_string();
    assert!(err.starts_with("/nonexistent/x.png:"), "{err}");
    let err = read_image(&dir().join("index.json")).unwrap_err().to_string();
    assert!(err.contains("index.json") && err.contains("not a PNG or JPEG"), "{err}");
    let err = read_image(&dir().join("depth_z_zip.exr")).unwrap_err().to_string();
    assert!(!err.contains('\n'), "{err}");
}
