//! Scenes made on the CPU while the GPU denoises: a thread takes the pending scenes from their
//! source in order (rendering the procedural bed, or reading scenes rendered elsewhere) and cuts
//! each into its images (depth, control image, mask, annotations, files encoded), a few scenes
//! ahead of the denoiser and no more.

use super::controls::control_file;
use super::plan::ImageFiles;
use super::settings::DatasetSettings;
use crate::error::{Error, Result};
use serde_json::{json, Value};
use std::sync::mpsc::{sync_channel, Receiver};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use vkdiff_pipeline::RgbImage;
use vkdiff_render::coco::{annotations, instance_masks, Annotation};
use vkdiff_render::control::{control_image, ControlKind};
use vkdiff_render::crops::crop_frame;
use vkdiff_render::crops::CropWindow;
use vkdiff_render::exr::encode_single_channel;
use vkdiff_render::png_out::{gray16, rgb8};
use vkdiff_render::preview::shaded_image;
use vkdiff_scenes::SourceFrame;

/// One image's share of its scene, ready to be denoised and written.
pub struct SceneImage {
    pub index: u64,
    pub scene: u64,
    pub scene_seed: u64,
    /// The scene's folder or file, for scenes rendered elsewhere.
    pub scene_name: Option<String>,
    /// The crop number, for images cut from a frame by `--crops`.
    pub crop: Option<usize>,
    /// Where the image lies in the frame, as the COCO image entry records it.
    pub window: Value,
    pub camera: Value,
    /// The ControlNet's input: the depth as `vkdiff scene` writes control.png.
    pub control: RgbImage,
    pub depth_exr: Vec<u8>,
    pub control_png: Vec<u8>,
    /// The other controls (`--controls`, and those the ControlNets see).
    pub controls: Vec<SceneControl>,
    pub mask_png: Vec<u8>,
    /// The crop's shaded render, and as a PNG: img2img's start (`--init-strength`), or a
    /// render-only set's image.
    pub init: Option<(RgbImage, Vec<u8>)>,
    /// COCO annotations, ids = the instance ids in the mask.
    pub annotations: Vec<Annotation>,
    /// Its region masks and strength map on the latent grid, with a set that has them.
    pub regions: Option<Vec<Vec<f32>>>,
    pub strength: Option<Vec<f64>>,
    /// The strength map as a picture: its file and PNG.
    pub strength_png: Option<(String, Vec<u8>)>,
}

impl SceneImage {
    /// The image's COCO entry as far as the scene makes it: files, size, where it lies in the
    /// frame and the camera.
    pub fn entry(&self, files: &ImageFiles) -> Value {
        let mut entry = json!({
            "id": self.index + 1,
            "file_name": files.image,
            "width": self.control.width,
            "height": self.control.height,
            "depth_file": files.depth,
            "control_file": files.control,
            "mask_file": files.mask,
            "scene_seed": self.scene_seed,
            "crop": self.window,
            "camera": self.camera,
        });
        entry["crop"]["index"] = json!(self.crop);
        if !self.controls.is_empty() {
            let files: serde_json::Map<String, Value> =
                self.controls.iter().map(|c| (c.kind.name().to_string(), json!(c.file))).collect();
            entry["control_files"] = Value::Object(files);
        }
        if let Some(name) = &self.scene_name {
            entry["scene"] = json!(name);
        }
        if let Some((file, _)) = &self.strength_png {
            entry["strength_file"] = json!(file);
        }
        entry
    }

    /// The annotations as the dataset records them: image id `index + 1`, set-wide ids left to
    /// the merge.
    pub fn dataset_annotations(&self) -> Vec<Annotation> {
        self.annotations.iter().cloned().map(|a| a.in_dataset(self.index + 1)).collect()
    }

    /// The files that come from the scene, as (name, bytes), in the order they are written.
    pub fn scene_files<'a>(&'a self, files: &'a ImageFiles) -> Vec<(&'a str, &'a [u8])> {
        let mut out = vec![
            (files.depth.as_str(), self.depth_exr.as_slice()),
            (&files.control, &self.control_png),
            (&files.mask, &self.mask_png),
        ];
        out.extend(self.controls.iter().map(|c| (c.file.as_str(), c.png.as_slice())));
        out.extend(self.strength_png.iter().map(|(file, png)| (file.as_str(), png.as_slice())));
        out
    }

    /// The image of control `kind` the ControlNets see.
    pub fn control_image(&self, kind: ControlKind) -> &RgbImage {
        match self.controls.iter().find(|c| c.kind == kind) {
            Some(c) => &c.image,
            None if kind == ControlKind::Depth => &self.control,
            None => unreachable!("the settings make every control a ControlNet sees"),
        }
    }
}

/// A control beside the depth control: its image, its file and its PNG.
pub struct SceneControl {
    pub kind: ControlKind,
    pub file: String,
    pub png: Vec<u8>,
    pub image: RgbImage,
}

/// The renderer thread: images arrive in the order of `scenes`; the thread's busy time is
/// returned when it is joined.
pub struct SceneStream {
    pub images: Receiver<Result<SceneImage>>,
    pub thread: JoinHandle<Duration>,
}

/// Starts rendering `scenes` (scene number, the indices of its images to make) on `threads`
/// worker threads (0: one per core), at most `ahead` images ahead of the reader.
pub fn render_scenes(
    settings: &DatasetSettings,
    scenes: Vec<(u64, Vec<u64>)>,
    threads: usize,
    ahead: usize,
) -> SceneStream {
    let (send, images) = sync_channel(ahead.max(1));
    let settings = settings.clone();
    let thread = std::thread::spawn(move || {
        let mut busy = Duration::ZERO;
        let render = || {
            for (scene, indices) in scenes {
                let start = Instant::now();
                let made = scene_images(&settings, scene, &indices);
                busy += start.elapsed();
                let items: Vec<Result<SceneImage>> = match made {
                    Ok(images) => images.into_iter().map(Ok).collect(),
                    Err(e) => vec![Err(e)],
                };
                for item in items {
                    if send.send(item).is_err() {
                        return;
                    }
                }
            }
        };
        if let Err(e) = vkdiff_render::with_threads(threads, render) {
            let _ = send.send(Err(Error::Config(format!("starting the scene threads: {e}"))));
        }
        busy
    });
    SceneStream { images, thread }
}

/// The images `indices` of scene number `scene`.
fn scene_images(settings: &DatasetSettings, scene: u64, indices: &[u64]) -> Result<Vec<SceneImage>> {
    let seed = settings.seed + scene;
    let SourceFrame { frame, shaded } = settings.source.frame(scene, seed)?;
    let windows = settings.windows(scene, seed)?;
    let per = settings.images_per_scene();
    let cropped = settings.crops.count > 0;
    Ok(indices
        .iter()
        .map(|&index| {
            let k = (index % per) as usize;
            let window = windows[k];
            let part = crop_frame(&frame, window, settings.crops.min_fraction);
            let (w, h) = (part.width, part.height);
            let pixels = control_image(&part.depth, settings.control_depth);
            let depth_control = ImageFiles::new(index, settings.images()).control;
            let controls = settings
                .controls
                .images(&part, (frame.width, frame.height), window)
                .into_iter()
                .map(|(kind, rgb)| SceneControl {
                    kind,
                    file: control_file(&depth_control, kind),
                    png: rgb8(w, h, &rgb),
                    image: RgbImage { width: w as usize, height: h as usize, pixels: rgb },
                })
                .collect();
            let camera = part.camera.as_ref().map_or(Value::Null, |c| {
                let c = c.to_json();
                json!({
                    "K": c["K"],
                    "width": c["width"],
                    "height": c["height"],
                    "crop_offset_px": c["crop_offset_px"],
                    "T_world_camera_opencv": c["T_world_camera_opencv"]["matrix"],
                })
            });
            // The renderer's own image, cut as the frame is; else the frame lit from its depth.
            let init = settings.wants_shaded().then(|| {
                let shaded = match &shaded {
                    Some(rgb) => cut_rgb(rgb, frame.width(), window),
                    None => shaded_image(&part),
                };
                let png = rgb8(w, h, &shaded);
                (RgbImage { width: w as usize, height: h as usize, pixels: shaded }, png)
            });
            let regions = settings.regions.of_image(&part);
            let strength_png = regions.strength_picture.map(|grey| {
                let rgb: Vec<u8> = grey.iter().flat_map(|&v| [v, v, v]).collect();
                (strength_file(&ImageFiles::new(index, settings.images()).init), rgb8(w, h, &rgb))
            });
            SceneImage {
                index,
                regions: regions.masks,
                strength: regions.strength,
                strength_png,
                scene,
                scene_seed: seed,
                scene_name: settings.source.scene(scene).name.map(String::from),
                crop: cropped.then_some(k),
                window: json!({"offset_px": [window.x0, window.y0], "size_px": [window.width, window.height]}),
                camera,
                depth_exr: encode_single_channel(w, h, "Z", &part.depth),
                control_png: rgb8(w, h, &pixels),
                controls,
                mask_png: gray16(w, h, &part.ids),
                init,
                annotations: annotations(&part, &instance_masks(&part)),
                control: RgbImage { width: w as usize, height: h as usize, pixels },
            }
        })
        .collect())
}

/// The strength map's file beside its init image: `init/NNNNNN.strength.png`.
pub fn strength_file(init: &str) -> String {
    format!("{}.strength.png", init.strip_suffix(".png").unwrap_or(init))
}

/// The pixels of an RGB image `width` wide under `window`.
fn cut_rgb(rgb: &[u8], width: usize, window: CropWindow) -> Vec<u8> {
    let (x0, w) = (window.x0 as usize, window.width as usize);
    (window.y0 as usize..(window.y0 + window.height) as usize)
        .flat_map(|y| rgb[(y * width + x0) * 3..(y * width + x0 + w) * 3].iter().copied())
        .collect()
}
