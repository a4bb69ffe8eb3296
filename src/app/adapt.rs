//! `mousepose adapt`: the arguments, handed to [`crate::engine::adapt`], and what it measured,
//! trained and judged printed as a table (or one JSON object with `--json`).

use crate::app::Outcome;
use crate::app::output::{print, print_json};
use crate::app::progress::Bars;
use crate::engine::adapt::{ADAPT_FILE, AdaptOptions, AdaptSummary, FrameRange, adapt};
use crate::vision::measure::{Spread, Unlabelled};
use clap::Args;
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct AdaptArgs {
    /// The lab's recordings (what `replay` reads: sessions, MoSeq layouts).
    #[arg(value_name = "RECORDING", required = true)]
    pub recordings: Vec<PathBuf>,
    /// The models directory to write (body.forest, orientation.json, paws.xml, adapt.json);
    /// `replay --models DIR` and `run --models DIR` use it. Never the bundled models.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// The frames of each recording to learn from, FIRST:LAST (Python's slice; all by
    /// default).
    #[arg(long, value_name = "FIRST:LAST", default_value = ":")]
    pub learn_frames: FrameRange,
    /// The frames to judge the models on, before and after (all by default: judging needs no
    /// labels, but frames not learnt from say more).
    #[arg(long, value_name = "FIRST:LAST", default_value = ":")]
    pub judge_frames: FrameRange,
    /// Do not replay the recordings to judge the models before and after.
    #[arg(long)]
    pub no_judge: bool,
    /// Frames measured per recording, at most (spread over the frames to learn from).
    #[arg(long, value_name = "N", default_value_t = 1500, value_parser = clap::value_parser!(u64).range(10..=1_000_000))]
    pub frames: u64,
    /// Training images rendered of the fitted mouse.
    #[arg(long, value_name = "N", default_value_t = 3000, value_parser = clap::value_parser!(u64).range(50..=1_000_000))]
    pub images: u64,
    /// Trees of the body forest.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub trees: u32,
    /// Depth of its trees.
    #[arg(long, default_value_t = 18, value_parser = clap::value_parser!(u32).range(1..=40))]
    pub depth: u32,
    /// Random tests per split node.
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u32).range(1..=10_000))]
    pub tests: u32,
    /// Mouse pixels drawn per training image.
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub pixels: u32,
    /// Seed of the rendering and the training.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// The depth camera's intrinsics for uncalibrated recordings (as `replay --intrinsics`).
    #[arg(long, value_name = "FILE")]
    pub intrinsics: Option<PathBuf>,
    /// A PNG mask of the arena (as `replay --roi`).
    #[arg(long, value_name = "FILE")]
    pub roi: Option<PathBuf>,
    /// Body-forest workers of the judging replays (0: one per core).
    #[arg(long, default_value_t = 0)]
    pub workers: usize,
    /// Replace the output directory if it is not empty.
    #[arg(long)]
    pub force: bool,
    /// Print adapt.json's content as one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// `mousepose adapt`.
pub fn command(args: &AdaptArgs) -> Outcome {
    let options = AdaptOptions {
        recordings: args.recordings.clone(),
        out: args.out.clone(),
        force: args.force,
        learn: args.learn_frames,
        judge: args.judge_frames,
        judge_models: !args.no_judge,
        frames: usize::try_from(args.frames).unwrap_or(usize::MAX),
        images: args.images,
        trees: args.trees,
        depth: args.depth,
        tests: args.tests,
        pixels: args.pixels,
        seed: args.seed,
        intrinsics: args.intrinsics.clone(),
        roi: args.roi.clone(),
        workers: args.workers,
    };
    let summary = adapt(&options, &Bars::default())?;
    if args.json {
        print_json(&summary)?;
    } else {
        print(&text(&summary))?;
    }
    Ok(())
}

fn spread(s: &Spread) -> String {
    format!("{:.1} ({:.1}-{:.1})", s.p50, s.p25, s.p75)
}

fn figures(u: &Unlabelled) -> String {
    format!(
        "head leading {:.1} % of {} moving frames; {} frames in brief reversals, {:.1} flips per 1,000 frames; {:.1} % of the body's joints on the mouse; axis against the mask's {:.1} deg (p95 {:.1})",
        100.0 * u.head_leading,
        u.moving_frames,
        u.brief_reversals,
        u.flips_per_1000,
        100.0 * u.joints_on_mouse,
        u.axis_deg_median,
        u.axis_deg_p95
    )
}

/// The summary as the terminal shows it.
pub fn text(s: &AdaptSummary) -> String {
    let mut t = String::new();
    for r in &s.recordings {
        let _ = writeln!(
            t,
            "{:?}: frames {}..{} of {}, {} measured, mouse found in {}; camera {:.0} mm above the floor, {:.2} mm a pixel, floor noise {}",
            r.recording,
            r.learn.start,
            r.learn.end,
            r.frames,
            r.measured,
            r.found,
            r.camera_height_mm,
            r.mm_per_px,
            r.floor_noise_mm
                .map_or_else(|| "unknown".to_owned(), |n| format!("{n:.1} mm"))
        );
    }
    let _ = writeln!(
        t,
        "{:>10} {:>22} {:>22} {:>22}",
        "mm", "your mice", "our standard mouse", "fitted"
    );
    for (name, get) in [
        (
            "length",
            (|b: &crate::vision::measure::BodySummary| b.length_mm) as fn(&_) -> Spread,
        ),
        ("width", |b| b.width_mm),
        ("height", |b| b.height_mm),
    ] {
        let _ = writeln!(
            t,
            "{name:>10} {:>22} {:>22} {:>22}",
            spread(&get(&s.measured)),
            spread(&get(&s.standard)),
            spread(&get(&s.fitted))
        );
    }
    let _ = writeln!(
        t,
        "{:>10} {:>21.0}% {:>21.0}% {:>21.0}%",
        "tail seen",
        100.0 * s.measured.tail_seen,
        100.0 * s.standard.tail_seen,
        100.0 * s.fitted.tail_seen
    );
    let b = &s.build;
    let _ = writeln!(
        t,
        "build: size x{:.3}, girth x{:.3}, back height x{:.3}, tail shown {:.0} %; rendered {} images at {:.0} mm, noise {:.1} mm",
        b.scale,
        b.girth,
        b.height,
        100.0 * b.tail_shown,
        s.trained.images,
        s.render_camera_height_mm,
        s.render_noise_mm
    );
    let _ = writeln!(
        t,
        "trained: body forest {} trees, {} nodes ({:.0} s), orientation model on {} views (training accuracy {:.3})",
        s.trained.body_trees,
        s.trained.body_nodes,
        s.trained.body_seconds,
        s.trained.orientation_views,
        s.trained.orientation_training_accuracy
    );
    for j in &s.judged {
        let _ = writeln!(
            t,
            "judged on frames {}..{} of {:?}, without labels:",
            j.frames.start, j.frames.end, j.recording
        );
        if let Some(b) = &j.bundled {
            let _ = writeln!(t, "  bundled: {}", figures(b));
        }
        let _ = writeln!(t, "  adapted: {}", figures(&j.adapted));
    }
    let _ = writeln!(
        t,
        "models in {:?} ({ADAPT_FILE} says how they were made); use them with replay --models or run --models ({:.0} s)",
        s.out, s.elapsed_s
    );
    t
}
