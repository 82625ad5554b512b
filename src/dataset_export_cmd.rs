//! `vkdiff dataset export DIR --format F --out OUT`: a finished set in a trainer's layout.

use anyhow::Result;
use clap::{Args, ValueEnum};
use std::path::PathBuf;
use vkdiff_args::Progress;
use vkdiff_dataset::{
    export, Exclusion, ExportFormat, ExportOptions, Exported, Split, SplitFractions, AUDIT_KINDS, EXCLUDED,
};

/// Write a finished set in a trainer's layout (COCO splits, YOLO, YOLO pose, WebDataset, Hugging
/// Face, BOP).
///
/// The set must be merged (annotations.json written). Splits are by scene: every crop of a scene
/// goes to the same split, and a scene's split does not change when the set grows. DIR is only
/// read; OUT appears whole or not at all. The geometric labels (keypoints, poses, 3D boxes,
/// amodal masks, cameras) go into coco as annotations.json has them, into yolo-pose and into bop.
/// `--exclude-flagged` and `--min-boundary-score` leave out what `vkdiff dataset audit` found.
#[derive(Args, Debug)]
pub struct ExportArgs {
    /// The dataset folder.
    dir: PathBuf,
    /// coco: train/val/test.json beside the set's files; yolo: Ultralytics segmentation
    /// (images/, labels/, data.yaml); yolo-pose: Ultralytics pose (boxes and keypoints,
    /// kpt_shape; no flip_idx, so Ultralytics turns flips off); webdataset: tar shards; hf: a
    /// Hugging Face image folder; bop: BOP scenes ({split}/{scene}/ with rgb/, depth/,
    /// mask_visib/, mask/ and scene_camera, scene_gt, scene_gt_info JSON; models/models_info.json),
    /// every instance needing a pose.
    #[arg(long, value_enum)]
    format: FormatArg,
    /// The folder to write (new, or replaced with --force).
    #[arg(long)]
    out: PathBuf,
    /// Share of the scenes for validation.
    #[arg(long, default_value_t = 0.1, allow_negative_numbers = true)]
    val_fraction: f64,
    /// Share of the scenes for testing.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    test_fraction: f64,
    /// Seed of the split (the same seed gives the same split).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Copy the files rather than hard-link them (links fall back to copies across file systems).
    #[arg(long)]
    copy: bool,
    /// Replace OUT if it exists.
    #[arg(long)]
    force: bool,
    /// webdataset: close each shard once it holds this many MB.
    #[arg(long, default_value_t = 1000)]
    shard_size: u64,
    /// Leave out the images `vkdiff dataset audit` flagged (DIR/audit.json): with any flag, or
    /// with one of KINDS (`--exclude-flagged=missing,invented`; kinds: missing, invented,
    /// poor_mask, weak_boundary). The kept and dropped lists go into OUT/excluded.json.
    #[arg(long, num_args = 0..=1, require_equals = true, default_missing_value = "all", value_delimiter = ',', value_name = "KINDS")]
    exclude_flagged: Option<Vec<String>>,
    /// Leave out the images whose boundary F-score in the audit is below S (0 to 1).
    #[arg(long, value_name = "S")]
    min_boundary_score: Option<f64>,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum FormatArg {
    Coco,
    Yolo,
    YoloPose,
    Webdataset,
    Hf,
    Bop,
}

pub fn run(args: &ExportArgs) -> Result<()> {
    let format = match args.format {
        FormatArg::Coco => ExportFormat::Coco,
        FormatArg::Yolo => ExportFormat::Yolo,
        FormatArg::YoloPose => ExportFormat::YoloPose,
        FormatArg::Webdataset => ExportFormat::WebDataset,
        FormatArg::Hf => ExportFormat::Hf,
        FormatArg::Bop => ExportFormat::Bop,
    };
    let options = ExportOptions {
        format,
        splits: SplitFractions { val: args.val_fraction, test: args.test_fraction, seed: args.seed },
        copy: args.copy,
        force: args.force,
        shard_bytes: args.shard_size.saturating_mul(1_000_000),
        exclude: Exclusion {
            kinds: match args.exclude_flagged.as_deref() {
                Some([all]) if all == "all" => AUDIT_KINDS.map(str::to_string).to_vec(),
                Some(kinds) => kinds.to_vec(),
                None => Vec::new(),
            },
            min_boundary_score: args.min_boundary_score,
        },
    };
    let bar = Progress::new("export", "image");
    let exported = export(&args.dir, &args.out, &options, &mut |done, total| bar.update(done, total))?;
    println!("{}", summary(args, &exported));
    Ok(())
}

fn summary(args: &ExportArgs, e: &Exported) -> String {
    let splits: Vec<String> = Split::ALL
        .iter()
        .filter(|s| e.images.contains_key(s) || **s == Split::Train)
        .map(|s| {
            let (images, scenes) = (*e.images.get(s).unwrap_or(&0), *e.scenes.get(s).unwrap_or(&0));
            format!("{} {} of {}", s.name(), count(images, "image"), count(scenes, "scene"))
        })
        .collect();
    let mut line = format!(
        "wrote {} ({}): {}; {}",
        args.out.display(),
        args.format.to_possible_value().map_or(String::new(), |v| v.get_name().to_string()),
        splits.join(", "),
        count(e.annotations, "annotation"),
    );
    if e.linked + e.copied > 0 {
        line += &format!("; {} linked, {} copied", count(e.linked, "file"), e.copied);
    }
    if let Some(fit) = e.polygons {
        line += &format!(
            "; polygons of {} instances ({:.1} points each) cover their masks with IoU min {:.3}, mean {:.3}",
            fit.instances,
            fit.points as f64 / fit.instances.max(1) as f64,
            fit.min_iou,
            fit.mean_iou
        );
    }
    if e.shards > 0 {
        line += &format!("; {} shards", e.shards);
    }
    if let Some(k) = e.keypoints {
        line += &format!("; {} per label line (kpt_shape [{k}, 3])", count(k as u64, "keypoint"));
    }
    if let Some(dropped) = e.dropped {
        line += &format!("; {} left out by the audit (listed in {EXCLUDED})", count(dropped, "image"));
    }
    if let Some(bop) = e.bop {
        line += &format!("; {}", count(bop.scene_folders, "scene folder"));
        if bop.without_amodal > 0 {
            line += &format!(
                "; {} without an amodal mask: their silhouette in scene_gt_info.json is the visible mask",
                count(bop.without_amodal, "instance")
            );
        }
        if bop.coarse_depth > 0 {
            line += &format!(
                "; {} too deep for 0.1 mm depth steps: stored in 1 or 10 mm",
                count(bop.coarse_depth, "image")
            );
        }
    }
    line
}

/// `1 scene`, `3 scenes`.
fn count(n: u64, thing: &str) -> String {
    format!("{n} {thing}{}", if n == 1 { "" } else { "s" })
}
