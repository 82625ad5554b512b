//! The controls a scene's labels give, held to tools/make_control_fixtures.py, which computes them
//! with numpy alone from the scene fixtures' files (touching, occluding and cut-off instances, a
//! ground plane of category 0, a sky at infinity): edges and segmentation exactly, normals within
//! one level of 255 (the two sides round the same f64 arithmetic, in another order).

use std::path::{Path, PathBuf};
use vkdiff_formats::image::read_image;
use vkdiff_render::coco::Category;
use vkdiff_render::control::edges::{edge_image, DEFAULT_DEPTH_JUMP};
use vkdiff_render::control::normals::{normal_image, Intrinsics};
use vkdiff_render::control::segmentation::{category_colours, segmentation_image};
use vkdiff_scenes::{RenderedScenes, SceneSource, DEFAULT_FAR};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures")
}

fn expected(format: &str, scene: &str, control: &str) -> Vec<u8> {
    let path = fixtures().join("controls").join(format).join(scene).join(format!("{control}.png"));
    read_image(&path).unwrap_or_else(|e| panic!("{e}")).pixels
}

/// The categories as the numpy side renames them to ADE20K classes.
fn ade_named(categories: &[Category]) -> Vec<Category> {
    let rename = |name: &str| -> String {
        match name {
            "leaf" => "plant".into(),
            "branch" => "tree".into(),
            other => other.into(),
        }
    };
    categories.iter().map(|c| Category { name: rename(&c.name), ..c.clone() }).collect()
}

#[test]
fn controls_match_numpy_on_every_fixture_scene() {
    let mut checked = 0;
    for format in ["folders", "blenderproc"] {
        let scenes = RenderedScenes::open(&fixtures().join("scenes").join(format), "object", DEFAULT_FAR).unwrap();
        let colours = category_colours(&scenes.categories());
        let ade_colours = category_colours(&ade_named(&scenes.categories()));
        assert!(ade_colours.iter().filter(|c| c.ade20k.is_some()).count() == 2, "{ade_colours:?}");
        for k in 0..scenes.available().unwrap() {
            let name = scenes.scene(k).name.unwrap().trim_end_matches(".hdf5").to_string();
            let frame = scenes.frame(k, 0).unwrap().frame;
            let width = frame.width as usize;
            let categories: Vec<u32> = frame.instances.iter().map(|i| i.category_id).collect();
            let edges = edge_image(&frame.ids, &frame.depth, width, DEFAULT_DEPTH_JUMP);
            assert!(edges == expected(format, &name, "edges"), "{format}/{name}: edges differ");
            let segmentation = segmentation_image(&frame.ids, &categories, &colours);
            assert!(segmentation == expected(format, &name, "segmentation"), "{format}/{name}: segmentation");
            let ade = segmentation_image(&frame.ids, &categories, &ade_colours);
            assert!(ade == expected(format, &name, "segmentation_ade"), "{format}/{name}: ADE20K colours");
            let camera = Intrinsics::blender_default(frame.width, frame.height);
            let normals = normal_image(&frame.ids, &frame.depth, width, camera, DEFAULT_DEPTH_JUMP);
            let numpy = expected(format, &name, "normals");
            let off: Vec<u8> = normals.iter().zip(&numpy).map(|(a, b)| a.abs_diff(*b)).collect();
            let worst = off.iter().copied().max().unwrap();
            let count = off.iter().filter(|&&d| d > 0).count();
            assert!(worst <= 1 && count * 1000 <= off.len(), "{format}/{name}: normals {count} values off, by {worst}");
            checked += 1;
        }
    }
    assert_eq!(checked, 5, "three scene folders and two BlenderProc frames");
}
