//! `vkdiff dataset preview`: a self-contained HTML page of a finished set's images with their
//! instance outlines drawn over them (one colour per instance; with several categories, one
//! colour per category and a legend), switchable to the depth, the control image and the init
//! image, each captioned with its seed, prompt and instance count; and a contact sheet PNG of
//! the same images with their outlines. Where the set has them, amodal outlines and keypoints
//! are layers of their own, drawn over whichever picture shows.

use super::canvas::Canvas;
use super::export::{FinishedSet, SetImage, SplitFractions};
use super::preview_flagged::{box_outline, Flagged, ImageFlags, WARNING};
use super::preview_geometry::{amodal_overlay, keypoint_overlay, Overlay};
use super::preview_page::page;
use super::preview_pictures::{box_down, data_uri, depth_picture, escape, read_ids, rgba_png};
use crate::error::{Error, Result};
use serde_json::Value;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use vkdiff_formats::atomic::write_atomic;
use vkdiff_pipeline::images::read_image;
use vkdiff_pipeline::RgbImage;
use vkdiff_render::png_out::rgb8;

/// What a preview wrote.
pub struct Preview {
    pub html: PathBuf,
    pub sheet: PathBuf,
    pub images: usize,
}

/// Thumbnails of the contact sheet fit this square.
const THUMB: usize = 256;

/// Writes the preview of `count` images of the set in `dir`, spread evenly over it (over those
/// its audit flagged, when `only_flagged`), to `html` (pictures at most `max_side` pixels on a
/// side, 0: full size) and the contact sheet beside it (`html` with `.png`);
/// `progress(done, total)` per image.
pub fn preview(
    dir: &Path,
    html: &Path,
    count: usize,
    max_side: usize,
    only_flagged: bool,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Preview> {
    if count == 0 {
        return Err(Error::Setting(vkdiff_setting::Message::setting("count").then(" must be at least 1")));
    }
    let set = FinishedSet::read(dir, &SplitFractions { val: 0.0, test: 0.0, seed: 0 })?;
    let flagged = only_flagged.then(|| Flagged::read(dir)).transpose()?;
    let id_of = |image: &SetImage| image.entry["id"].as_u64().unwrap_or_default();
    let pool: Vec<&SetImage> = match &flagged {
        Some(f) => set.images.iter().filter(|i| f.0.contains_key(&id_of(i))).collect(),
        None => set.images.iter().collect(),
    };
    if pool.is_empty() {
        return Err(Error::Config(format!("the audit of {} flagged no image: nothing to preview", dir.display())));
    }
    let n = count.min(pool.len());
    let chosen: Vec<&SetImage> = (0..n).map(|k| pool[k * pool.len() / n]).collect();
    let categories = Categories::of(&set);
    let mut figures = String::new();
    let mut kinds: Vec<String> = chosen
        .iter()
        .flat_map(|image| image.entry["control_files"].as_object().into_iter().flat_map(|m| m.keys().cloned()))
        .chain(chosen.iter().any(|image| image.entry["strength_file"].is_string()).then(|| STRENGTH.to_string()))
        .collect();
    kinds.sort();
    kinds.dedup();
    let columns = (n as f64).sqrt().ceil().max(1.0) as usize;
    let rows = n.div_ceil(columns);
    // With several categories, a legend row above the thumbnails.
    let top = if categories.by_category() { 30 } else { 0 };
    let mut sheet = Canvas::new(columns * (THUMB + 8) + 8, rows * (THUMB + 30) + 8 + top, [24, 26, 27]);
    if categories.by_category() {
        let mut x = 8i64;
        for (name, color) in &categories.legend {
            sheet.rect(x, 8, 14, 14, *color);
            sheet.text(x + 20, 10, name, 2, [230, 230, 230]);
            x += 20 + Canvas::text_width(name, 2) + 24;
        }
    }
    for (k, image) in chosen.iter().enumerate() {
        let flags = flagged.as_ref().and_then(|f| f.0.get(&id_of(image)));
        let layers = Layers::read(&set.dir, image, &categories, flags)?;
        figures += &figure(image, &layers.shrunk(max_side), flags);
        let thumb = layers.outlined_thumbnail();
        let (x, y) = (8 + (k % columns) * (THUMB + 8), 8 + top + (k / columns) * (THUMB + 30));
        sheet.blit(x as i64, y as i64, thumb.width, thumb.height, &thumb.pixels);
        let label = format!("{}  N={}", image.entry["id"], image.annotations.len());
        sheet.text(x as i64, (y + THUMB + 8) as i64, &label, 2, [230, 230, 230]);
        progress(k + 1, n);
    }
    let what = if flagged.is_some() { "flagged images" } else { "images" };
    let title = format!("{} · {} of {} {what}", dir.display(), n, pool.len());
    let overlays: Vec<&str> =
        ["amodal", "keypoints"].into_iter().filter(|class| figures.contains(&format!("class=\"{class}\""))).collect();
    write_atomic(html, page(&title, &categories.legend_html(), &figures, &kinds, &overlays).as_bytes())?;
    let sheet_path = html.with_extension("png");
    write_atomic(&sheet_path, &sheet.png())?;
    Ok(Preview { html: html.to_path_buf(), sheet: sheet_path, images: n })
}

/// The set's categories and the colours outlines take: one per instance for a set of one
/// category, one per category (with a legend) for several.
struct Categories {
    /// Category id → its colour.
    colors: std::collections::BTreeMap<u64, [u8; 3]>,
    /// Name and colour of each category, in the set's order.
    legend: Vec<(String, [u8; 3])>,
    /// Category id → its keypoints' skeleton (pairs numbered from 1).
    skeletons: std::collections::BTreeMap<u64, Vec<[usize; 2]>>,
}

impl Categories {
    fn of(set: &FinishedSet) -> Categories {
        let listed = set.categories.as_array().cloned().unwrap_or_default();
        let mut colors = std::collections::BTreeMap::new();
        let mut legend = Vec::new();
        let mut skeletons = std::collections::BTreeMap::new();
        for (k, c) in listed.iter().enumerate() {
            let color = category_color(k);
            colors.insert(c["id"].as_u64().unwrap_or(0), color);
            legend.push((c["name"].as_str().unwrap_or("?").to_string(), color));
            let skeleton = serde_json::from_value(c["skeleton"].clone()).unwrap_or_default();
            skeletons.insert(c["id"].as_u64().unwrap_or(0), skeleton);
        }
        Categories { colors, legend, skeletons }
    }

    fn by_category(&self) -> bool {
        self.legend.len() > 1
    }

    /// The page's legend: a swatch and the name of each category.
    fn legend_html(&self) -> String {
        if !self.by_category() {
            return String::new();
        }
        let mut html = String::from("<div class=\"legend\">");
        for (name, [r, g, b]) in &self.legend {
            let _ = write!(html, r#"<span><i style="background:rgb({r},{g},{b})"></i>{}</span>"#, escape(name));
        }
        html + "</div>"
    }

    /// Each mask id's outline colour in `image`.
    fn palette(&self, image: &SetImage) -> Vec<[u8; 3]> {
        let ids = image.annotations.iter().filter_map(|a| a["mask_id"].as_u64());
        let mut palette: Vec<[u8; 3]> = (0..=ids.max().unwrap_or(0) as u16).map(instance_color).collect();
        if self.by_category() {
            for a in &image.annotations {
                let (Some(id), Some(category)) = (a["mask_id"].as_u64(), a["category_id"].as_u64()) else { continue };
                palette[id as usize] = self.colors.get(&category).copied().unwrap_or([255, 255, 255]);
            }
        }
        palette
    }
}

/// A colour per category, far apart for the first few.
fn category_color(k: usize) -> [u8; 3] {
    const FIRST: [[u8; 3]; 8] = [
        [255, 80, 80],
        [80, 200, 255],
        [255, 220, 60],
        [120, 255, 120],
        [255, 120, 255],
        [255, 160, 60],
        [160, 120, 255],
        [60, 255, 220],
    ];
    FIRST.get(k).copied().unwrap_or_else(|| instance_color(k as u16 + 1))
}

/// One image's pictures: the image, its instance ids, and its guides where the set has them.
struct Layers {
    image: RgbImage,
    ids: Vec<u16>,
    /// Each mask id's outline colour.
    palette: Vec<[u8; 3]>,
    depth: Option<RgbImage>,
    control: Option<RgbImage>,
    init: Option<RgbImage>,
    /// The other controls (`--controls`), by kind.
    controls: Vec<(String, RgbImage)>,
    /// The amodal outlines and the keypoints, where the image has them.
    amodal: Option<Overlay>,
    keypoints: Option<Overlay>,
    /// Boxes drawn in the warning colour (the audit's invented detections), x, y, w, h.
    warnings: Vec<[f64; 4]>,
    /// The factor the picture was scaled down by.
    scale: usize,
}

impl Layers {
    fn read(dir: &Path, image: &SetImage, categories: &Categories, flags: Option<&ImageFlags>) -> Result<Layers> {
        let file = |key: &str| image.entry[key].as_str().map(|f| dir.join(f));
        let picture = |key: &str| file(key).map(|p| read_image(&p)).transpose();
        let image_rgb = read_image(&dir.join(image.file_name()))?;
        let ids = match file("mask_file") {
            Some(path) => read_ids(&path, image_rgb.width, image_rgb.height)?,
            None => vec![0; image_rgb.width * image_rgb.height],
        };
        let depth = file("depth_file").map(|p| depth_picture(&p)).transpose()?;
        let mut palette = categories.palette(image);
        for a in image
            .annotations
            .iter()
            .filter(|a| flags.is_some_and(|f| a["id"].as_u64().is_some_and(|id| f.instances.contains(&id))))
        {
            if let Some(slot) = a["mask_id"].as_u64().and_then(|id| palette.get_mut(id as usize)) {
                *slot = WARNING;
            }
        }
        let listed = image.entry["control_files"].as_object().into_iter().flatten();
        // The strength map shows as one more layer beside the controls.
        let strength = image.entry["strength_file"].as_str().map(|f| (STRENGTH.to_string(), Value::from(f)));
        let controls = listed
            .map(|(kind, file)| (kind.clone(), file.clone()))
            .chain(strength)
            .filter_map(|(kind, file)| Some((kind, dir.join(file.as_str()?))))
            .map(|(kind, path)| Ok((kind, read_image(&path)?)))
            .collect::<Result<_>>()?;
        let (w, h) = (image_rgb.width, image_rgb.height);
        let color = |a: &Value| {
            let id = a["mask_id"].as_u64().unwrap_or(0) as usize;
            palette.get(id).copied().unwrap_or([255, 255, 255])
        };
        let skeleton =
            |a: &Value| categories.skeletons.get(&a["category_id"].as_u64().unwrap_or(0)).cloned().unwrap_or_default();
        Ok(Layers {
            amodal: amodal_overlay(image, w, h, color),
            keypoints: keypoint_overlay(image, w, h, skeleton, color),
            depth,
            control: picture("control_file")?,
            init: picture("init_file")?,
            controls,
            image: image_rgb,
            ids,
            palette,
            warnings: flags.map(|f| f.boxes.clone()).unwrap_or_default(),
            scale: 1,
        })
    }

    /// The layers at most `max_side` pixels on a side (0: as they are): pictures box-averaged
    /// and ids sampled, by the same whole factor, so that a page of large images stays light.
    fn shrunk(&self, max_side: usize) -> Layers {
        let (w, h) = (self.image.width, self.image.height);
        let f = if max_side == 0 { 1 } else { w.max(h).div_ceil(max_side).max(1) };
        let (sw, sh) = (w.div_ceil(f), h.div_ceil(f));
        let ids =
            (0..sw * sh).map(|p| self.ids[((p / sw) * f + f / 2).min(h - 1) * w + ((p % sw) * f + f / 2).min(w - 1)]);
        Layers {
            image: box_down(&self.image, f),
            ids: ids.collect(),
            palette: self.palette.clone(),
            depth: self.depth.as_ref().map(|d| box_down(d, f)),
            control: self.control.as_ref().map(|c| box_down(c, f)),
            init: self.init.as_ref().map(|i| box_down(i, f)),
            controls: self.controls.iter().map(|(kind, c)| (kind.clone(), box_down(c, f))).collect(),
            amodal: self.amodal.as_ref().map(|o| o.pooled(f)),
            keypoints: self.keypoints.as_ref().map(|o| o.pooled(f)),
            warnings: self.warnings.clone(),
            scale: self.scale * f,
        }
    }

    /// Transparent but for each instance's outline, in its colour, as an RGBA PNG.
    fn outlines_png(&self) -> Vec<u8> {
        let (w, h) = (self.image.width, self.image.height);
        let mut rgba = vec![0u8; w * h * 4];
        for (p, color) in self.outline_pixels() {
            rgba[4 * p..4 * p + 4].copy_from_slice(&[color[0], color[1], color[2], 255]);
        }
        rgba_png(w as u32, h as u32, &rgba)
    }

    /// Pixels of an instance that touch another id, with the instance's colour; then the
    /// warning boxes' outlines.
    fn outline_pixels(&self) -> impl Iterator<Item = (usize, [u8; 3])> + '_ {
        let (w, h) = (self.image.width, self.image.height);
        let boxes = self.warnings.iter().flat_map(move |&b| box_outline(b, (w, h), self.scale)).map(|p| (p, WARNING));
        (0..w * h)
            .filter_map(move |p| {
                let id = self.ids[p];
                let (x, y) = (p % w, p / w);
                let differs = |q: usize| self.ids[q] != id;
                let edge = id != 0
                    && ((x > 0 && differs(p - 1))
                        || (x + 1 < w && differs(p + 1))
                        || (y > 0 && differs(p - w))
                        || (y + 1 < h && differs(p + w)));
                edge.then(|| (p, self.palette.get(id as usize).copied().unwrap_or_else(|| instance_color(id))))
            })
            .chain(boxes)
    }

    /// The image with its outlines, scaled (nearest: outlines stay sharp) to fit [`THUMB`].
    fn outlined_thumbnail(&self) -> RgbImage {
        let mut pixels = self.image.pixels.clone();
        for (p, color) in self.outline_pixels() {
            pixels[3 * p..3 * p + 3].copy_from_slice(&color);
        }
        let (w, h) = (self.image.width, self.image.height);
        let scale = THUMB as f64 / w.max(h) as f64;
        let (tw, th) = (((w as f64 * scale) as usize).max(1), ((h as f64 * scale) as usize).max(1));
        let mut thumb = Vec::with_capacity(tw * th * 3);
        for y in 0..th {
            for x in 0..tw {
                let p = (y * h / th) * w + x * w / tw;
                thumb.extend_from_slice(&pixels[3 * p..3 * p + 3]);
            }
        }
        RgbImage { width: tw, height: th, pixels: thumb }
    }
}

/// A bright colour per instance id, far from its neighbours' (golden-angle hues).
fn instance_color(id: u16) -> [u8; 3] {
    let hue = (id as f64 * 137.507_764) % 360.0;
    let f = |n: f64| {
        let k = (n + hue / 60.0) % 6.0;
        (255.0 * (1.0 - (k.min(4.0 - k).clamp(0.0, 1.0)) * 0.85)) as u8
    };
    [f(5.0), f(3.0), f(1.0)]
}

/// The strength map's layer (`init/NNNNNN.strength.png`).
const STRENGTH: &str = "strength";

fn figure(image: &SetImage, layers: &Layers, flags: Option<&ImageFlags>) -> String {
    let e = &image.entry;
    let mut html = String::from("<figure><div class=\"stack\">");
    let base = |class: &str, png: &[u8]| format!("<img class=\"{class}\" src=\"{}\" alt=\"{class}\">", data_uri(png));
    let png = |i: &RgbImage| rgb8(i.width as u32, i.height as u32, &i.pixels);
    html += &base("image", &png(&layers.image));
    for (class, picture) in [("depth", &layers.depth), ("control", &layers.control), ("init", &layers.init)] {
        if let Some(picture) = picture {
            html += &base(class, &png(picture));
        }
    }
    for (kind, picture) in &layers.controls {
        html += &base(&format!("control-{kind}"), &png(picture));
    }
    html += &base("outline", &layers.outlines_png());
    for (class, overlay) in [("amodal", &layers.amodal), ("keypoints", &layers.keypoints)] {
        if let Some(o) = overlay {
            html += &base(class, &rgba_png(o.width as u32, o.height as u32, &o.rgba));
        }
    }
    let mut caption = format!("#{} · {} instances · scene {}", e["id"], image.annotations.len(), e["scene_seed"]);
    if let Some(seed) = e["seed"].as_u64() {
        let _ = write!(caption, " · seed {seed}");
    }
    if let Some(k) = e["crop"]["index"].as_u64() {
        let _ = write!(caption, " · crop {k}");
    }
    if let Some(f) = flags {
        let _ = write!(caption, " · flagged: {}", f.kinds.join(", "));
    }
    let mut prompt = e["prompt"].as_str().map_or_else(|| "shaded render (no prompt)".to_string(), str::to_string);
    for (name, region) in e["region_prompts"].as_object().into_iter().flatten() {
        let _ = write!(prompt, " · {name}: {}", region.as_str().unwrap_or_default());
    }
    let _ = writeln!(
        html,
        "</div><figcaption>{}<br><span class=\"prompt\">{}</span></figcaption></figure>",
        escape(&caption),
        escape(&prompt)
    );
    html
}
