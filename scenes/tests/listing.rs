//! Listing rendered scenes reads headers and side files, not pixels: a scene whose pixel data is
//! damaged behind a sound header is listed with its size and categories, and refused, naming the
//! file, when its frame is read.

use std::path::{Path, PathBuf};
use vkdiff_scenes::{RenderedScenes, SceneSource, DEFAULT_FAR};

fn fixture(scene: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/scenes/folders").join(scene)
}

/// A folder holding a copy of the fixture's orchard-a.
fn copy_of_orchard_a(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("vkdiff-scenes-{}-{name}", std::process::id()));
    let scene = dir.join("orchard-a");
    std::fs::create_dir_all(&scene).unwrap();
    for entry in std::fs::read_dir(fixture("orchard-a")).unwrap().flatten() {
        std::fs::copy(entry.path(), scene.join(entry.file_name())).unwrap();
    }
    dir
}

#[test]
fn listing_reads_no_pixels_and_the_frame_reads_them() {
    let dir = copy_of_orchard_a("damaged");
    let sound_dir = copy_of_orchard_a("sound");
    let sound = RenderedScenes::open(&sound_dir, "object", DEFAULT_FAR).unwrap();
    let frame = sound.frame(0, 0).unwrap().frame;
    // The instance map cut in half: its header whole, its image data short.
    let instances = dir.join("orchard-a/instances.png");
    let bytes = std::fs::read(&instances).unwrap();
    std::fs::write(&instances, &bytes[..bytes.len() / 2]).unwrap();
    let listed = RenderedScenes::open(&dir, "object", DEFAULT_FAR).unwrap();
    let scene = listed.scene(0);
    assert_eq!((scene.width, scene.height), (frame.width, frame.height));
    assert_eq!(scene.name, Some("orchard-a"));
    assert_eq!(listed.categories(), sound.categories());
    let refused = listed.frame(0, 0).err().expect("a damaged instance map is refused when read").to_string();
    assert!(refused.contains("scene orchard-a: instances.png"), "{refused}");
    for folder in [dir, sound_dir] {
        std::fs::remove_dir_all(folder).unwrap();
    }
}
