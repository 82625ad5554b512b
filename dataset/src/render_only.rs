//! `vkdiff dataset --render-only`: the set whose images are the scenes' shaded renders, the
//! baseline every diffusion-refined set is compared with. The same scenes, crops, masks and
//! COCO as a diffusion run with the same scene flags, and each image byte for byte that run's
//! `init/` file; no model and no device.

use super::disk::DiskGuard;
use super::folder::{Dataset, Pending};
use super::run::{Progress, Report, RunOptions, StageTimes};
use super::scenes::render_scenes;
use super::settings::DatasetSettings;
use super::stop::{interrupted, stop_requested};
use crate::error::{Error, Result};
use serde_json::json;
use std::time::Instant;

/// Writes the `pending` images of the render-only `dataset`, `disk` checked before each.
pub fn write_renders(
    dataset: &Dataset,
    disk: &DiskGuard,
    settings: &DatasetSettings,
    pending: Pending,
    options: &RunOptions,
    on_progress: &mut dyn FnMut(Progress),
) -> Result<Report> {
    let (mut done, total) = (pending.done, pending.done + pending.images());
    let stream = render_scenes(settings, pending.scenes, options.threads, 2 * options.threads.max(2));
    let mut times = StageTimes::default();
    let mut made = 0;
    loop {
        let waited = Instant::now();
        if stop_requested() {
            return Err(interrupted(done, total));
        }
        let Ok(scene) = stream.images.recv() else { break };
        times.waiting += waited.elapsed();
        let scene = scene?;
        disk.check(total - done)?;
        let start = Instant::now();
        let files = dataset.files(scene.index);
        let (_, shaded) =
            scene.init.as_ref().ok_or_else(|| Error::Config("a render without its shaded image".into()))?;
        let mut outputs = scene.scene_files(&files);
        outputs.push((&files.image, shaded));
        let mut entry = scene.entry(&files);
        entry["source"] = json!("render");
        disk.written.add(dataset.write_image(scene.index, &outputs, entry, scene.dataset_annotations())?);
        times.write += start.elapsed();
        made += 1;
        done += 1;
        on_progress(Progress::Images { done, total });
    }
    times.scene = stream.thread.join().map_err(|_| crate::run::scene_thread_panicked())?;
    Ok(Report { made, times, recordings: 0 })
}
