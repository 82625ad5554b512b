//! `vkdiff dataset preview DIR`: a page to look at a finished set with its masks.

use anyhow::Result;
use clap::Args;
use std::path::PathBuf;
use vkdiff_args::Progress;
use vkdiff_dataset::preview;

/// A page to look at a finished set: images with their instance outlines, and a contact sheet.
///
/// A self-contained HTML page of the images with each instance's outline drawn over them (one
/// colour per instance), switchable to depth, control and init images (or by the page's #depth,
/// #control, #init, and #image,nooutlines), and a contact-sheet PNG beside it.
#[derive(Args, Debug)]
pub struct PreviewArgs {
    /// The dataset folder.
    dir: PathBuf,
    /// The page to write; the contact sheet goes beside it as .png [default: DIR/preview.html].
    #[arg(long)]
    out: Option<PathBuf>,
    /// Images shown, spread evenly over the set.
    #[arg(long, default_value_t = 24)]
    count: usize,
    /// Pictures on the page at most this many pixels on a side (0: full size), so that a page
    /// of 1024² images stays light; the contact sheet is made from the full images.
    #[arg(long, default_value_t = 512)]
    max_side: usize,
    /// Only the images `vkdiff dataset audit` flagged, their flagged instances outlined and
    /// invented detections boxed in red (reads DIR/audit.json).
    #[arg(long)]
    flagged: bool,
}

pub fn run(args: &PreviewArgs) -> Result<()> {
    let html = args.out.clone().unwrap_or_else(|| args.dir.join("preview.html"));
    let bar = Progress::new("preview", "image");
    let made =
        preview(&args.dir, &html, args.count, args.max_side, args.flagged, &mut |done, total| bar.update(done, total))?;
    println!("wrote {} ({} images) and its contact sheet {}", made.html.display(), made.images, made.sheet.display());
    Ok(())
}
