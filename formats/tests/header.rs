//! Sizes read from headers alone agree with the decoders' on every image of the fixtures: the
//! JPEG corpus (every kind of JPEG Pillow reads), the PNGs beside it and of every colour type, and the depth EXRs in each
//! compression; a file the header reader accepts is one the decoder sizes the same, and a file
//! with no depth channel is refused by both.

use std::path::PathBuf;
use vkdiff_formats::image::{depth_exr_size, grey_png_size, image_size, read_depth_exr, read_grey_png, read_image};

fn files(folder: &str, ext: &str) -> Vec<PathBuf> {
    let mut found: Vec<PathBuf> = std::fs::read_dir(vkdiff_testkit::fixture(folder))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == ext))
        .collect();
    found.sort();
    found
}

#[test]
fn image_headers_give_the_decoded_size() {
    let (jpegs, pngs) = (files("jpeg", "jpg"), files("jpeg", "png"));
    assert!(jpegs.len() >= 25 && pngs.len() >= 25, "the corpus is there");
    // Every PNG colour type and depth, and a photo.
    let images = [files("images", "png"), files("images", "jpg")].concat();
    for path in jpegs.iter().chain(&pngs).chain(&images) {
        // Files the decoder refuses (cut short, arithmetic-coded) may still have a sound header.
        if let Ok(image) = read_image(path) {
            let size = image_size(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            assert_eq!(size, (image.width, image.height), "{}", path.display());
        }
    }
}

#[test]
fn grey_png_headers_give_the_decoded_size_and_depth() {
    let scenes = vkdiff_testkit::fixture("scenes/folders");
    let mut checked = 0;
    for scene in std::fs::read_dir(scenes).unwrap().flatten() {
        let path = scene.path().join("instances.png");
        let grey = read_grey_png(&path).unwrap();
        assert_eq!(grey_png_size(&path).unwrap(), (grey.width, grey.height, grey.bits));
        checked += 1;
    }
    assert!(checked >= 3);
    let colour = &files("jpeg", "png")[0];
    assert!(grey_png_size(colour).is_err() && read_grey_png(colour).is_err(), "{}", colour.display());
}

#[test]
fn exr_headers_give_the_depth_channels_size() {
    let exrs = files("images", "exr");
    assert!(exrs.len() >= 4);
    for path in &exrs {
        match (read_depth_exr(path), depth_exr_size(path)) {
            (Ok((_, w, h)), Ok(size)) => assert_eq!(size, (w, h), "{}", path.display()),
            (Err(_), Err(_)) => {}
            (read, header) => panic!("{}: read {:?}, header {:?}", path.display(), read.map(|r| (r.1, r.2)), header),
        }
    }
}
