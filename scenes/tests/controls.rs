//! The controls a scene's labels give, held to tools/make_control_fixtures.py, which computes them
//! with numpy alone from the scene fixtures' files (touching, occluding and cut-off instances, a
//! ground plane of category 0, a sky at infinity): edges and segmentation exactly, normals within
//! one level of 255 (the two sides round the same f64 arithmetic, in another order). Scenes that
//! carry the renderer's normals (BlenderProc's `normals`, a scene folder's normals.exr) give the
//! numpy normals exactly where those are used, and within one level where the depth's stand in.

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
            assert!(frame.normals.is_none(), "{format}/{name} carries no normals");
            let width = frame.width as usize;
            let categories: Vec<u32> = frame.instances.iter().map(|i| i.category_id).collect();
            let edges = edge_image(&frame.ids, &frame.depth, width, DEFAULT_DEPTH_JUMP);
            assert!(edges == expected(format, &name, "edges"), "{format}/{name}: edges differ");
            let segmentation = segmentation_image(&frame.ids, &categories, &colours);
            assert!(segmentation == expected(format, &name, "segmentation"), "{format}/{name}: segmentation");
            let ade = segmentation_image(&frame.ids, &categories, &ade_colours);
            assert!(ade == expected(format, &name, "segmentation_ade"), "{format}/{name}: ADE20K colours");
            let camera = Intrinsics::blender_default(frame.width, frame.height);
            let normals =
                normal_image(&frame.ids, &frame.depth, frame.normals.as_deref(), width, camera, DEFAULT_DEPTH_JUMP);
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

#[test]
fn the_renderers_normals_are_the_numpy_ones() {
    let mut checked = 0;
    for format in ["folders", "blenderproc"] {
        let dir = fixtures().join("scenes/normals").join(format);
        let scenes = RenderedScenes::open(&dir, "object", DEFAULT_FAR).unwrap();
        for k in 0..scenes.available().unwrap() {
            let name = scenes.scene(k).name.unwrap().trim_end_matches(".hdf5").to_string();
            let frame = scenes.frame(k, 0).unwrap().frame;
            let given = frame.normals.as_deref().expect("the scene's normals");
            let (width, camera) = (frame.width as usize, Intrinsics::blender_default(frame.width, frame.height));
            let ours = normal_image(&frame.ids, &frame.depth, Some(given), width, camera, DEFAULT_DEPTH_JUMP);
            let from_depth = normal_image(&frame.ids, &frame.depth, None, width, camera, DEFAULT_DEPTH_JUMP);
            let numpy = expected("normals", &format!("{format}/{name}"), "normals");
            assert_eq!(ours.len(), numpy.len());
            // Where the renderer's normal is used (finite depth, a finite non-zero normal): exactly.
            let used = |p: usize| {
                let n = given[p];
                frame.depth[p].is_finite() && n.iter().all(|c| c.is_finite()) && n.iter().any(|&c| c != 0.0)
            };
            let (mut exact, mut fallback, mut worst) = (0, 0, 0);
            for p in 0..frame.depth.len() {
                let off = (0..3).map(|c| ours[3 * p + c].abs_diff(numpy[3 * p + c])).max().unwrap();
                if used(p) {
                    assert!(off == 0, "{format}/{name}: pixel {p} off by {off} where the renderer's normal is used");
                    exact += 1;
                } else {
                    worst = worst.max(off);
                    fallback += 1;
                }
            }
            assert!(worst <= 1, "{format}/{name}: the depth's normals off by {worst}");
            assert!(exact > frame.depth.len() / 2 && fallback > 1000, "{format}/{name}: {exact} and {fallback}");
            let differ = ours.chunks(3).zip(from_depth.chunks(3)).filter(|(a, b)| a != b).count();
            assert!(differ > frame.depth.len() / 4, "{format}/{name}: only {differ} pixels differ from the depth's");
            checked += 1;
        }
    }
    assert_eq!(checked, 3, "a scene folder and two BlenderProc frames");
}
