//! `vkdiff dataset stats` and `vkdiff dataset preview` on a render-only set: the figures against
//! the COCO file, the charts, and the preview page as headless Chromium shows it.

mod cli;

use cli::{chromium, render_set_of, scratch, screenshot, vkdiff};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Six scenes, twelve images of 128², made once.
fn set() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = scratch("look-set").join("set");
        render_set_of(&dir, 6, 320, 256, 128);
        dir
    })
}

fn ok(args: &[&str]) -> String {
    let out = vkdiff(args);
    assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// A PNG's width, height and pixels: RGB bytes for 8-bit colour, ids for 16-bit grey.
fn png_read(path: &Path) -> (usize, usize, Vec<u8>) {
    let mut reader =
        png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap())).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let frame = reader.next_frame(&mut buf).unwrap();
    buf.truncate(frame.buffer_size());
    (frame.width as usize, frame.height as usize, buf)
}

/// The bars of a chart, left to right: the height of each run of columns holding the bars' blue.
fn bar_heights(chart: &Path) -> Vec<usize> {
    let (w, h, rgb) = png_read(chart);
    let blue = |x: usize, y: usize| rgb[3 * (y * w + x)..][..3] == [70, 110, 170];
    let column: Vec<usize> = (0..w).map(|x| (0..h).filter(|&y| blue(x, y)).count()).collect();
    let mut bars = Vec::new();
    let mut x = 0;
    while x < w {
        if column[x] == 0 {
            x += 1;
            continue;
        }
        let start = x;
        while x < w && column[x] > 0 {
            x += 1;
        }
        assert!(column[start..x].iter().all(|&c| c == column[start]), "{}: a ragged bar", chart.display());
        bars.push(column[start]);
    }
    bars
}

fn png_size(path: &Path) -> (u32, u32) {
    let reader = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap())).read_info().unwrap();
    (reader.info().width, reader.info().height)
}

#[test]
fn stats_count_what_the_coco_file_holds() {
    let charts = scratch("look-stats");
    let stats: Value = serde_json::from_str(&ok(&[
        "dataset",
        "stats",
        set().to_str().unwrap(),
        "--json",
        "--charts",
        charts.to_str().unwrap(),
    ]))
    .unwrap();
    let coco: Value = serde_json::from_slice(&std::fs::read(set().join("annotations.json")).unwrap()).unwrap();
    let annotations = coco["annotations"].as_array().unwrap();
    let images = coco["images"].as_array().unwrap();
    assert_eq!((stats["images"].as_u64(), stats["scenes"].as_u64()), (Some(12), Some(6)));
    assert_eq!(stats["instances"].as_u64(), Some(annotations.len() as u64));
    let per: Vec<u64> =
        images.iter().map(|i| annotations.iter().filter(|a| a["image_id"] == i["id"]).count() as u64).collect();
    let s = &stats["instances_per_image"];
    assert_eq!((s["min"].as_u64(), s["max"].as_u64()), (per.iter().min().copied(), per.iter().max().copied()));
    let binned: u64 = s["histogram"].as_array().unwrap().iter().map(|b| b["count"].as_u64().unwrap()).sum();
    assert_eq!(binned, 12);
    let area = &stats["mask_area_px"];
    let classes: u64 = ["small", "medium", "large"].iter().map(|k| area[k].as_u64().unwrap()).sum();
    assert_eq!(classes, annotations.len() as u64);
    let small = annotations.iter().filter(|a| a["area"].as_u64().unwrap() < 32 * 32).count() as u64;
    assert_eq!(area["small"].as_u64(), Some(small));
    let cut = annotations
        .iter()
        .filter(|a| {
            let b: Vec<u64> = a["bbox"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap()).collect();
            b[0] == 0 || b[1] == 0 || b[0] + b[2] == 128 || b[1] + b[3] == 128
        })
        .count() as u64;
    assert!(cut > 0);
    assert_eq!(stats["cut_by_image_edge"]["instances"].as_u64(), Some(cut));
    assert_eq!(stats["sources"]["render"].as_u64(), Some(12));
    // The area histogram's bins as the COCO file fills them, and the chart's bars as tall as
    // their counts (the tallest the plot's full height; empty bins draw nothing).
    let bins = area["histogram"].as_array().unwrap();
    let counts: Vec<u64> = bins
        .iter()
        .map(|b| {
            let (from, to) = (b["from"].as_u64().unwrap(), b["to"].as_u64().unwrap());
            annotations.iter().filter(|a| (from..to).contains(&a["area"].as_u64().unwrap())).count() as u64
        })
        .collect();
    assert_eq!(bins.iter().map(|b| b["count"].as_u64().unwrap()).collect::<Vec<_>>(), counts);
    assert_eq!(counts.iter().sum::<u64>(), annotations.len() as u64, "bins that miss an area");
    let bars = bar_heights(&charts.join("mask_area.png"));
    let (tallest, most) = (*bars.iter().max().unwrap() as f64, *counts.iter().max().unwrap() as f64);
    let want: Vec<usize> =
        counts.iter().filter(|&&c| c > 0).map(|&c| (c as f64 / most * tallest).round() as usize).collect();
    assert!(tallest >= 200.0 && bars == want, "bars {bars:?}, counts {counts:?}");
    let (w, h) = png_size(&charts.join("instances_per_image.png"));
    assert!(w >= 360 && h >= 300, "instances_per_image.png: {w}×{h}");
    let text = ok(&["dataset", "stats", set().to_str().unwrap(), "--charts", charts.to_str().unwrap()]);
    assert!(text.contains("12 images of 6 scenes") && text.contains("cut by the image edge"), "{text}");
    let refused = vkdiff(&["dataset", "stats", charts.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(
        !refused.status.success() && stderr.lines().count() == 1 && stderr.contains("not a vkdiff dataset"),
        "{stderr}"
    );
}

#[test]
fn the_preview_page_shows_the_images_with_their_outlines_in_headless_chromium() {
    let dir = scratch("look-preview");
    let html = dir.join("page.html");
    let preview = |out: &Path, max_side: &str| {
        let (set, out) = (set().to_str().unwrap(), out.to_str().unwrap());
        ok(&["dataset", "preview", set, "--out", out, "--count", "4", "--max-side", max_side]);
    };
    preview(&html, "0");
    let page = std::fs::read_to_string(&html).unwrap();
    assert_eq!(page.matches("<figure>").count(), 4);
    // Image, depth, control and outlines each; a render-only set has no init images.
    assert_eq!(page.matches("src=\"data:image/png;base64,").count(), 16);
    assert!(!page.contains("src=\"images/") && !page.contains("file:"), "the page is self-contained");
    let (w, h) = png_size(&dir.join("page.png"));
    assert!(w >= 2 * 256 && h >= 2 * 256, "contact sheet {w}×{h}");
    first_tile_is_the_first_image_outlined(&dir.join("page.png"));
    // --max-side shrinks the page's pictures (the 128² images to 64²), not what they show.
    let small = dir.join("small.html");
    preview(&small, "64");
    let small_page = std::fs::read_to_string(&small).unwrap();
    assert_eq!(small_page.matches("<figure>").count(), 4);
    assert!(small_page.len() * 2 < page.len(), "{} bytes shrunk, {} bytes whole", small_page.len(), page.len());

    let browser = chromium();
    let url = format!("file://{}", html.display());
    let shown = screenshot(&browser, &url, &dir.join("shot.png"));
    let plain = screenshot(&browser, &format!("{url}#image,nooutlines"), &dir.join("plain.png"));
    let depth = screenshot(&browser, &format!("{url}#depth"), &dir.join("depth.png"));
    // The page's own background, not a browser error page.
    assert_eq!(shown[0], [24, 26, 27], "the screenshot is not the preview page");
    let colours: std::collections::HashSet<[u8; 3]> = shown.iter().copied().collect();
    assert!(colours.len() > 500, "only {} colours: the images did not render", colours.len());
    // Outlines are drawn over the image; the depth layer replaces it.
    let differ = |a: &[[u8; 3]], b: &[[u8; 3]]| a.iter().zip(b).filter(|(x, y)| x != y).count();
    assert!(differ(&shown, &plain) > 1000, "the outlines do not show");
    assert!(differ(&plain, &depth) > 10_000, "the depth toggle does not switch the layer");
    let refused = vkdiff(&["dataset", "preview", set().to_str().unwrap(), "--count", "0"]);
    assert!(String::from_utf8_lossy(&refused.stderr).contains("--count must be at least 1"));
}

/// The contact sheet's first tile (8 px in, 256² from a 128² image) is the set's first image,
/// each pixel a 2×2 block, except its instances' edge pixels (those with a 4-neighbour of
/// another id), which take one colour per instance.
fn first_tile_is_the_first_image_outlined(sheet: &Path) {
    let coco: Value = serde_json::from_slice(&std::fs::read(set().join("annotations.json")).unwrap()).unwrap();
    let first = &coco["images"][0];
    let (w, h, image) = png_read(&set().join(first["file_name"].as_str().unwrap()));
    let (_, _, mask) = png_read(&set().join(first["mask_file"].as_str().unwrap()));
    let ids: Vec<u16> = mask.chunks(2).map(|b| u16::from_be_bytes([b[0], b[1]])).collect();
    let (sw, _, tiles) = png_read(sheet);
    assert_eq!((w, h), (128, 128));
    let mut edge_colours: std::collections::HashMap<u16, std::collections::HashSet<[u8; 3]>> = Default::default();
    let (mut plain, mut edges) = (0, 0);
    for y in 0..h {
        for x in 0..w {
            let id = ids[y * w + x];
            let other = |nx: usize, ny: usize| ids[ny * w + nx] != id;
            let edge = id != 0
                && ((x > 0 && other(x - 1, y))
                    || (x + 1 < w && other(x + 1, y))
                    || (y > 0 && other(x, y - 1))
                    || (y + 1 < h && other(x, y + 1)));
            let block: Vec<[u8; 3]> = [(0, 0), (1, 0), (0, 1), (1, 1)]
                .iter()
                .map(|(dx, dy)| {
                    let at = 3 * ((8 + 2 * y + dy) * sw + 8 + 2 * x + dx);
                    [tiles[at], tiles[at + 1], tiles[at + 2]]
                })
                .collect();
            assert!(block.iter().all(|c| *c == block[0]), "tile pixel ({x}, {y}) is not a 2×2 block");
            if edge {
                edge_colours.entry(id).or_default().insert(block[0]);
                edges += 1;
            } else {
                assert_eq!(
                    block[0],
                    [image[3 * (y * w + x)], image[3 * (y * w + x) + 1], image[3 * (y * w + x) + 2]],
                    "tile pixel ({x}, {y})"
                );
                plain += 1;
            }
        }
    }
    assert!(edges > 100 && plain > 100, "{edges} edge pixels, {plain} others");
    assert!(edge_colours.values().all(|c| c.len() == 1), "an instance's outline in several colours");
}

/// The README's picture is what its two commands under it make, byte for byte (run them in the
/// README's own words, from a scratch folder).
#[test]
fn the_readme_picture_is_remade_by_the_commands_under_it() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    let commands: Vec<&str> =
        readme.lines().filter(|l| l.starts_with("vkdiff dataset ") && l.contains("beds")).take(2).collect();
    assert_eq!(
        commands.iter().map(|c| c.split('#').next().unwrap().trim()).collect::<Vec<_>>(),
        [
            "vkdiff dataset --render-only --out beds --count 4 --crops 2 --crop-size 512 --seed 0",
            "vkdiff dataset preview beds --count 8"
        ],
        "the README's commands under its picture changed"
    );
    let dir = scratch("readme-picture");
    std::fs::create_dir_all(&dir).unwrap();
    for command in &commands {
        let words: Vec<&str> = command.split('#').next().unwrap().split_whitespace().skip(1).collect();
        let out = cli::command().args(&words).current_dir(&dir).output().unwrap();
        assert!(out.status.success(), "{command}: {}", String::from_utf8_lossy(&out.stderr));
    }
    let made = std::fs::read(dir.join("beds/preview.png")).unwrap();
    let committed = std::fs::read(root.join("docs/images/render-only-beds.png")).unwrap();
    assert!(made == committed, "docs/images/render-only-beds.png is not what the README's commands make");
}
