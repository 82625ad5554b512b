//! Our EXR writer against an independent reader, the `exr` crate.

mod common;

use vkdiff_render::exr::encode_single_channel;

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn the_exr_crate_reads_back_every_value() {
    let (w, h) = (37u32, 45u32); // not a multiple of the 16-line block
    let mut values: Vec<f32> = (0..w * h).map(|i| 0.95 + 0.05 * ((i * 7919 % 1000) as f32 / 1000.0)).collect();
    values[3] = f32::INFINITY;
    let (rw, rh, name, back) = common::read_exr(&encode_single_channel(w, h, "Z", &values));
    assert_eq!((rw, rh, name.as_str()), (w as usize, h as usize, "Z"));
    assert_eq!(bits(&back), bits(&values));
}

#[test]
fn smooth_depth_compresses_and_incompressible_blocks_stay_readable() {
    let (w, h) = (64u32, 32u32);
    let smooth: Vec<f32> = (0..w * h).map(|i| 1.0 - (i % w) as f32 * 1e-4).collect();
    let bytes = encode_single_channel(w, h, "Z", &smooth);
    assert!(bytes.len() < (w * h * 4) as usize / 2, "{} bytes", bytes.len());
    assert_eq!(bits(&common::read_exr(&bytes).3), bits(&smooth));
    let noise: Vec<f32> =
        (0..w * h).map(|i| f32::from_bits((vkdiff_render::rng::mix64(i as u64) as u32) >> 2)).collect();
    assert_eq!(bits(&common::read_exr(&encode_single_channel(w, h, "Z", &noise)).3), bits(&noise));
}
