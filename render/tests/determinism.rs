//! Same seed, same bytes: whatever the number of threads, and whether a scene is written alone
//! or as part of a parallel dataset run.

mod common;

use vkdiff_render::output::{scene_folder_name, write_dataset, write_scene, OutputOptions};
use vkdiff_render::scene::SceneConfig;
use vkdiff_render::with_threads;

#[test]
fn same_seed_gives_byte_identical_files_on_one_or_two_threads() {
    let root = common::scratch("determinism");
    let options = OutputOptions { crops: 2, crop_size: 768, ..OutputOptions::default() };
    let config = SceneConfig::default();
    let write = |threads: usize, name: &str, seed: u64| {
        let dir = root.join(name);
        with_threads(threads, || write_scene(&dir, seed, &config, &options)).unwrap().unwrap();
        common::read_tree(&dir)
    };
    let one = write(1, "one-thread", 4);
    let two = write(2, "two-threads", 4);
    let names: Vec<&String> = one.keys().collect();
    assert_eq!(names.len(), 8 + 2 * 7, "{names:?}");
    assert_eq!(one.keys().collect::<Vec<_>>(), two.keys().collect::<Vec<_>>());
    for (name, bytes) in &one {
        assert!(bytes == &two[name], "{name} differs between 1 and 2 threads");
    }
    let other = write(2, "other-seed", 5);
    assert_ne!(one["depth.exr"], other["depth.exr"]);
    assert_ne!(one["annotations.json"], other["annotations.json"]);
    std::fs::remove_dir_all(root).unwrap();
}

#[test]
fn dataset_runs_write_numbered_scenes_and_resume() {
    let root = common::scratch("dataset");
    let config = SceneConfig { width: 480, height: 270, ..SceneConfig::default() };
    let options = OutputOptions { crops: 1, crop_size: 256, ..OutputOptions::default() };
    let dataset = root.join("beds");
    let report = with_threads(2, || write_dataset(&dataset, 7, 3, &config, &options)).unwrap().unwrap();
    assert_eq!((report.written, report.skipped), (3, 0));
    let mut folders: Vec<String> =
        std::fs::read_dir(&dataset).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    folders.sort();
    assert_eq!(folders, ["000007", "000008", "000009"]);
    // A scene of the dataset is the scene written alone.
    let alone = root.join("alone");
    with_threads(1, || write_scene(&alone, 8, &config, &options)).unwrap().unwrap();
    assert_eq!(common::read_tree(&alone), common::read_tree(&dataset.join(scene_folder_name(8))));
    // A second run finds every folder complete and writes nothing.
    let again = write_dataset(&dataset, 7, 3, &config, &options).unwrap();
    assert_eq!((again.written, again.skipped), (0, 3));
    std::fs::remove_dir_all(root).unwrap();
}
