//! `vkdiff bench scene`: frames per second of the scene pipeline, stage by stage, against the
//! paper's 12 s per frame (Blender/Cycles with BAT on an RTX 2000 Ada).

use std::fmt;
use std::time::{Duration, Instant};

use serde_json::json;

use crate::coco::{coco_json, instance_masks};
use crate::control::ControlDepth;
use crate::error::Result;
use crate::frame::Frame;
use crate::output::frame_files;
use crate::preview::preview_image;
use crate::raster::rasterize;
use crate::scene::{Scene, SceneConfig};

pub const PAPER_SECONDS_PER_FRAME: f64 = 12.0;

/// The timed stages, in pipeline order; the first five make depth + masks + COCO.
pub const STAGES: [&str; 6] = ["bed", "project", "raster", "label", "coco", "files"];
const ANNOTATION_STAGES: usize = 5;

#[derive(Clone, Debug)]
pub struct BenchReport {
    pub width: u32,
    pub height: u32,
    pub threads: usize,
    pub first_seed: u64,
    /// Per frame, per stage.
    pub times: Vec<[Duration; STAGES.len()]>,
    pub visible: Vec<usize>,
    pub triangles: Vec<usize>,
}

/// Renders `frames` scenes from `first_seed` after one untimed warm-up frame.
pub fn bench_scene(first_seed: u64, frames: usize, config: &SceneConfig) -> Result<BenchReport> {
    config.validate()?;
    let mut report = BenchReport {
        width: config.width,
        height: config.height,
        threads: rayon::current_num_threads(),
        first_seed,
        times: Vec::new(),
        visible: Vec::new(),
        triangles: Vec::new(),
    };
    time_frame(first_seed, config)?;
    for i in 0..frames as u64 {
        let (times, visible, triangles) = time_frame(first_seed.wrapping_add(i), config)?;
        report.times.push(times);
        report.visible.push(visible);
        report.triangles.push(triangles);
    }
    Ok(report)
}

fn time_frame(seed: u64, config: &SceneConfig) -> Result<([Duration; STAGES.len()], usize, usize)> {
    let mut times = [Duration::ZERO; STAGES.len()];
    let mut clock = Instant::now();
    let mut lap = |stage: usize| {
        times[stage] = clock.elapsed();
        clock = Instant::now();
    };
    let scene = Scene::build(seed, config)?;
    lap(0);
    let triangles = scene.project();
    lap(1);
    let raster = rasterize(config.width, config.height, &triangles);
    lap(2);
    let frame = Frame::from_raster(raster, &scene.camera, &scene.bed);
    lap(3);
    let annotations = coco_json(&frame, &instance_masks(&frame), &[crate::coco::mushroom_category()], json!({}));
    lap(4);
    // Every file of the folder, encoded in memory (no disk), COCO included once more.
    let files = frame_files(&frame, json!({}), ControlDepth::Inverse, "");
    let preview = preview_image(&frame);
    lap(5);
    std::hint::black_box((annotations, files, preview));
    Ok((times, frame.instances.len(), triangles.iter().map(Vec::len).sum()))
}

impl BenchReport {
    fn mean_ms(&self, stage: usize) -> f64 {
        self.times.iter().map(|t| t[stage].as_secs_f64()).sum::<f64>() * 1e3 / self.times.len().max(1) as f64
    }

    /// Mean seconds per frame over the first `stages` stages.
    fn seconds_per_frame(&self, stages: usize) -> f64 {
        (0..stages).map(|s| self.mean_ms(s)).sum::<f64>() / 1e3
    }

    pub fn annotation_fps(&self) -> f64 {
        1.0 / self.seconds_per_frame(ANNOTATION_STAGES)
    }

    pub fn mean_visible(&self) -> f64 {
        self.visible.iter().sum::<usize>() as f64 / self.visible.len().max(1) as f64
    }
}

impl fmt::Display for BenchReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = self.times.len();
        writeln!(
            f,
            "vkdiff bench scene: {}×{}, {n} frames (seeds {}..{}), {} threads",
            self.width,
            self.height,
            self.first_seed,
            self.first_seed.wrapping_add(n as u64),
            self.threads
        )?;
        writeln!(f, "{:<10} {:>9}", "stage", "ms/frame")?;
        for (s, name) in STAGES.iter().enumerate() {
            writeln!(f, "{name:<10} {:>9.2}", self.mean_ms(s))?;
        }
        let annotate = self.seconds_per_frame(ANNOTATION_STAGES);
        let all = self.seconds_per_frame(STAGES.len());
        writeln!(
            f,
            "depth + masks + COCO: {:.1} ms/frame = {:.1} frames/s, {:.0}× the paper's \
            {PAPER_SECONDS_PER_FRAME} s/frame",
            annotate * 1e3,
            1.0 / annotate,
            PAPER_SECONDS_PER_FRAME / annotate
        )?;
        writeln!(
            f,
            "with every file encoded (EXR, PNGs, JSON, preview): {:.1} ms/frame = {:.1} frames/s",
            all * 1e3,
            1.0 / all
        )?;
        let mean = self.mean_visible();
        let sd = (self.visible.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / n.max(1) as f64).sqrt();
        let (lo, hi) =
            (self.visible.iter().min().copied().unwrap_or(0), self.visible.iter().max().copied().unwrap_or(0));
        writeln!(f, "visible instances per frame: mean {mean:.1}, sd {sd:.1}, min {lo}, max {hi} (paper: 145)")?;
        write!(
            f,
            "triangles drawn per frame (after culling): mean {:.0}",
            self.triangles.iter().sum::<usize>() as f64 / n.max(1) as f64
        )
    }
}
