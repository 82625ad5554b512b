//! Bad arguments: one clear error naming the flag or folder, and nothing left on disk.

mod common;

use std::path::Path;

use vkdiff_render::output::{write_dataset, write_scene, OutputOptions};
use vkdiff_render::scene::SceneConfig;
use vkdiff_render::RenderError;

fn small() -> SceneConfig {
    SceneConfig { width: 320, height: 180, ..SceneConfig::default() }
}

fn entries(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> =
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    names.sort();
    names
}

/// Runs a failing write into a fresh folder and returns its one-line message, checking that
/// the folder is still empty afterwards (no scene, no staging leftovers).
fn fails(name: &str, config: &SceneConfig, options: &OutputOptions) -> String {
    let root = common::scratch(name);
    let err = write_scene(&root.join("scene"), 3, config, options).unwrap_err().to_string();
    assert!(!err.contains('\n'), "one line: {err}");
    assert!(entries(&root).is_empty(), "{name} left {:?}", entries(&root));
    let dataset_err = write_dataset(&root.join("beds"), 3, 2, config, options).unwrap_err().to_string();
    assert_eq!(dataset_err, err);
    assert!(entries(&root).is_empty(), "{name} (dataset) left {:?}", entries(&root));
    err
}

#[test]
fn a_crop_larger_than_the_frame_is_refused() {
    let err = fails("crop-too-big", &small(), &OutputOptions { crops: 3, crop_size: 200, ..OutputOptions::default() });
    assert_eq!(err, "crop_size 200: must lie in [1, 180] to fit the 320×180 frame");
}

#[test]
fn negative_density_and_out_of_range_settings_are_refused() {
    let mut config = small();
    config.bed.density = -1.0;
    assert_eq!(
        fails("negative-density", &config, &OutputOptions::default()),
        "density -1: must be a number ≥ 0 (mushrooms per m²)"
    );
    config.bed.density = f64::NAN;
    assert!(fails("nan-density", &config, &OutputOptions::default()).starts_with("density NaN"));
    let config = SceneConfig { width: 8, ..small() };
    assert!(fails("tiny-frame", &config, &OutputOptions::default()).starts_with("width 8"));
    let options = OutputOptions { crop_min_fraction: 1.5, ..OutputOptions::default() };
    assert!(fails("min-fraction", &small(), &options).starts_with("crop_min_fraction 1.5"));
}

#[test]
fn a_dataset_needs_scenes_and_seeds() {
    let root = common::scratch("count");
    let err = write_dataset(&root.join("beds"), 0, 0, &small(), &OutputOptions::default()).unwrap_err();
    assert_eq!(err.to_string(), "count 0: must be at least 1");
    let err = write_dataset(&root.join("beds"), u64::MAX, 2, &small(), &OutputOptions::default()).unwrap_err();
    assert!(err.to_string().starts_with("count 2: runs past the largest seed"), "{err}");
    assert!(entries(&root).is_empty());
}

#[test]
fn an_unwritable_folder_is_named_and_nothing_is_written() {
    let root = common::scratch("unwritable");
    // A folder cannot be made inside a file (permissions would not stop root).
    let file = root.join("not-a-folder");
    std::fs::write(&file, b"x").unwrap();
    let err = write_scene(&file.join("scene"), 1, &small(), &OutputOptions::default()).unwrap_err();
    assert!(matches!(err, RenderError::Io { .. }), "{err:?}");
    assert!(err.to_string().starts_with(&format!("cannot create folder {}: ", file.display())), "{err}");
    assert_eq!(entries(&root), ["not-a-folder"]);
    assert_eq!(std::fs::read(&file).unwrap(), b"x");
}

#[test]
fn an_existing_scene_is_kept_unless_replacing() {
    let root = common::scratch("existing");
    let dir = root.join("scene");
    std::fs::create_dir(&dir).unwrap();
    std::fs::write(dir.join("mine.txt"), b"keep").unwrap();
    let err = write_scene(&dir, 1, &small(), &OutputOptions::default()).unwrap_err();
    assert_eq!(err.to_string(), format!("{}: output exists already (pass replace to replace it)", dir.display()));
    assert_eq!(entries(&dir), ["mine.txt"]);
    write_scene(&dir, 1, &small(), &OutputOptions { replace: true, ..OutputOptions::default() }).unwrap();
    assert_eq!(
        entries(&dir),
        [
            "annotations.json",
            "camera.json",
            "categories.json",
            "control.png",
            "depth.exr",
            "instances.png",
            "preview.png",
            "shaded.png"
        ]
    );
    assert_eq!(entries(&root), ["scene"], "no staging or replaced folder left behind");
}
