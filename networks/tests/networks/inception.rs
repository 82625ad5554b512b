//! torch-fidelity's FID InceptionV3 against torch-fidelity itself (tools/make_fid_fixtures.py):
//! the real architecture with reproducible random weights, images of many sizes and PNG kinds,
//! 2048 pooled features each.

use std::path::PathBuf;
use vkdiff_formats::SafeTensors;
use vkdiff_networks::{InceptionV3, RandomInception, RgbPixels, INCEPTION_FEATURES};
use vkdiff_runtime::Dtype;
use vkdiff_testkit::ctx;
use vkdiff_testkit::fixture;

/// The fixture images of `folder` (sorted), with torch-fidelity's features for them. On the GPU
/// paths (`VKDIFF_GPU_PATHS=1`), whose tiled convolutions are some 15× slower on lavapipe, the
/// last image of each folder: the composition is proven there and every image on the default
/// paths.
fn images(folder: &str) -> (Vec<vkdiff_formats::RgbImage>, Vec<f32>) {
    let mut files: Vec<PathBuf> =
        std::fs::read_dir(fixture("fid").join(folder)).unwrap().map(|e| e.unwrap().path()).collect();
    files.sort();
    let (shape, mut want) =
        SafeTensors::open(&fixture("fid").join("features.safetensors")).unwrap().values(folder).unwrap();
    assert_eq!(shape, [files.len(), INCEPTION_FEATURES]);
    if vkdiff_testkit::settings().gpu_paths {
        let first = files.len() - 1;
        files.drain(..first);
        want.drain(..first * INCEPTION_FEATURES);
    }
    (files.iter().map(|f| vkdiff_formats::image::read_image(f).unwrap()).collect(), want)
}

/// Largest |got − want| over the largest |want|, per image.
fn worst_relative(got: &[f32], want: &[f32]) -> f64 {
    got.chunks(INCEPTION_FEATURES)
        .zip(want.chunks(INCEPTION_FEATURES))
        .map(|(g, w)| {
            let scale = w.iter().fold(0f64, |m, &v| m.max(v.abs() as f64));
            g.iter().zip(w).fold(0f64, |m, (&a, &b)| m.max((a as f64 - b as f64).abs())) / scale
        })
        .fold(0.0, f64::max)
}

fn check(dtype: Dtype, batch: usize, tolerance: f64) {
    let net = InceptionV3::load(&ctx(), dtype, &RandomInception::new()).unwrap();
    for folder in ["real", "fake"] {
        let (images, want) = images(folder);
        let pixels: Vec<RgbPixels> =
            images.iter().map(|m| RgbPixels { data: &m.pixels, width: m.width, height: m.height }).collect();
        let got: Vec<f32> = pixels.chunks(batch).flat_map(|b| net.features(b).unwrap()).collect();
        let err = worst_relative(&got, &want);
        println!("{dtype:?} batch {batch} {folder}: worst |error| / max |feature| = {err:.2e}");
        assert!(
            err <= tolerance,
            "{dtype:?} {folder}: features off by {err:.3e} of their largest value (> {tolerance:.0e})"
        );
    }
}

#[test]
fn inception_features_match_torch_fidelity_f32() {
    // Images of different sizes share a batch: each is resized into its own slot.
    check(Dtype::F32, 4, 1e-4);
}

#[test]
fn inception_features_match_torch_fidelity_f16() {
    // f16 storage rounds every activation to 11 bits through 94 layers.
    check(Dtype::F16, 6, 5e-3);
}

#[test]
fn inception_weights_of_the_wrong_shape_are_named() {
    struct Narrow(RandomInception);
    impl vkdiff_networks::TensorSource for Narrow {
        fn values(&self, name: &str) -> vkdiff_networks::Result<(Vec<usize>, Vec<f32>)> {
            let (mut shape, v) = self.0.values(name)?;
            if name == "Mixed_6b.branch7x7_2.conv.weight" {
                shape.swap(2, 3);
            }
            Ok((shape, v))
        }
    }
    let err = InceptionV3::load(&ctx(), Dtype::F32, &Narrow(RandomInception::new()))
        .err()
        .expect("a transposed kernel is refused");
    assert!(err.to_string().contains("Mixed_6b.branch7x7_2.conv.weight"), "{err}");
}
