//! `mousepose replay`: a recorded or synthetic session (or a MoSeq recording) through the
//! pipeline; the work is [`crate::engine::replay`]. Several sessions make a batch
//! ([`crate::engine::batch`]).

use crate::app::Outcome;
use crate::app::output::{print, print_json, show_batch};
use crate::app::progress::{Bars, bar};
use crate::engine::batch::{BatchOptions, batch, is_batch};
use crate::engine::replay::{PICTURE_FILE, ReplayError, ReplayOptions, ReplaySummary, replay_with};
use crate::engine::{Failure, Interrupt};
use crate::runtime::sink::poses::POSES_FILE;
use crate::runtime::stream::lsl::LslConfig;
use crate::runtime::stream::{Endpoint, StreamConfig};
use clap::Args;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The summary as the terminal shows it.
pub fn summary_text(summary: &ReplaySummary, out: &Path) -> String {
    let mut text = String::new();
    let _ = writeln!(
        text,
        "{} pairs in {:.2} s ({:.0} pairs/s); poses in {:?}",
        summary.pairs,
        summary.elapsed_s,
        summary.throughput_pairs_per_s,
        out.join(POSES_FILE)
    );
    for (name, c) in &summary.cameras {
        let _ = writeln!(
            text,
            "{name:>6}: captured {}, paired {}, unpaired {}, dropped {} {:?}, lost before capture {:?}",
            c.captured, c.paired, c.unpaired, c.dropped_total, c.dropped, c.lost_before_capture
        );
    }
    for s in &summary.stages {
        let _ = writeln!(
            text,
            "{:>8}: {} in, {} out, p50 {:.2} ms, p99 {:.2} ms",
            s.name, s.items_in, s.items_out, s.latency.p50_ms, s.latency.p99_ms
        );
    }
    let _ = writeln!(
        text,
        "end to end: p50 {:.2} ms, p99 {:.2} ms",
        summary.end_to_end_latency.p50_ms, summary.end_to_end_latency.p99_ms
    );
    let w = &summary.world;
    let _ = writeln!(
        text,
        "depth camera {:.0} mm above the floor, tilted {:.1} deg; world frame from the {}; intrinsics: {} (f {:.1} px); arena {:.0} % of the image ({})",
        w.camera_height_mm,
        w.camera_tilt_deg,
        w.frame,
        w.intrinsics_from,
        w.fx,
        w.arena_share * 100.0,
        w.arena_from
    );
    for warning in &summary.warnings {
        let _ = writeln!(text, "warning: {warning}");
    }
    if let Some(n) = summary.duplicate_timestamps.filter(|&n| n > 0) {
        let _ = writeln!(
            text,
            "depth_ts.txt: {n} timestamps repeat the one before them; their frames are dropped (time_out_of_order)"
        );
    }
    if let Some(p) = &summary.pairing {
        let _ = writeln!(text, "pairing vs truth: {} of {} pairs match", p.matched, p.truth_pairs);
    }
    if summary.paw_model.is_none() && summary.cameras.contains_key("color") {
        let _ = writeln!(
            text,
            "no paw model ({} or {}) among the models: paws and limbs are in their default configuration",
            crate::runtime::models::PAWS_MODEL,
            crate::runtime::models::PAWS_NET_MODEL
        );
    }
    if let Some(mean) = summary.mean_error_mm {
        let _ = writeln!(text, "mean joint error vs truth: {mean:.2} mm");
        for (group, e) in &summary.group_error_mm {
            let _ = writeln!(text, "{group:>14}: {e:.2} mm");
        }
    }
    if let Some(error) = &summary.picture_error {
        let _ = writeln!(text, "no picture ({PICTURE_FILE}): {error}; the results are complete");
    }
    if let Some(o) = &summary.orientation {
        let share = |n: u64| 100.0 * n as f64 / o.frames as f64;
        let _ = writeln!(
            text,
            "head and tail swapped vs truth: {:.1} % of {} frames (each frame alone {:.1} %, the forest alone {:.1} %, the body shape alone {:.1} % of {}, a visible tail alone {:.1} % of {}); heading error otherwise {:.1} deg",
            share(o.flipped_tracked),
            o.frames,
            share(o.flipped_frame_alone),
            share(o.flipped_forest),
            100.0 * o.flipped_shape as f64 / o.shape_frames.max(1) as f64,
            o.shape_frames,
            100.0 * o.flipped_tail as f64 / o.tail_frames.max(1) as f64,
            o.tail_frames,
            o.heading_error_deg
        );
    }
    text
}

#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// The session directory (written by `record`, `run` or `synth session`, or a MoSeq
    /// recording). Several sessions, or a glob pattern (quoted), make a batch: each session
    /// goes to DIR/<session name>/ (a daemon's chunk to DIR/<run>-<chunk>/), finished ones
    /// are skipped, and DIR/batch.csv sums up; one batch at a time per DIR.
    #[arg(value_name = "SESSION", required = true)]
    pub sessions: Vec<PathBuf>,
    /// The directory to write poses.csv and summary.json into (a batch: the sessions' parent).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// The models directory (body.forest); the bundled models by default.
    #[arg(long, value_name = "DIR")]
    pub models: Option<PathBuf>,
    /// Deliver the frames at the pace they were recorded instead of as fast as possible.
    #[arg(long)]
    pub realtime: bool,
    /// Publish each pose on a live stream bound to ENDPOINT (tcp://IP:PORT or ipc://PATH), as
    /// `run` does with its config's `[stream]`: try `mousepose listen` and closed-loop code
    /// without cameras (with --realtime).
    #[arg(long, value_name = "ENDPOINT", value_parser = crate::app::parse::endpoint)]
    pub stream: Option<Endpoint>,
    /// Offer each pose as a Lab Streaming Layer stream called NAME (default `mousepose`), as
    /// `run` does with its config's `[lsl]`: what LabRecorder records (with --realtime).
    #[arg(long, value_name = "NAME", num_args = 0..=1, default_missing_value = "mousepose")]
    pub lsl: Option<String>,
    /// Beside each pose, the pose predicted MS milliseconds after its depth frame was taken
    /// (the rig's latency to what the pose drives), by each joint's velocity: in
    /// DIR/poses_predicted.csv, and on --stream and --lsl as `run` does with its config's
    /// `lead_ms`.
    #[arg(long, value_name = "MS", value_parser = crate::app::parse::lead_ms)]
    pub lead: Option<u64>,
    /// Pair as a live run with `[sync] partner_wait_ms = MS` does, from the recorded arrival
    /// stamps: a depth frame waits at most MS after its arrival for a nearer colour frame,
    /// then takes the nearest in (by default each depth frame pairs with its nearest).
    #[arg(long, value_name = "MS", value_parser = crate::app::parse::partner_ms)]
    pub partner_wait: Option<u64>,
    /// With --partner-wait: as `[sync] partner_reach_ms = MS`, the colour frame taken up to MS
    /// from the depth frame pairs at the end of the wait (by default up to the tolerance).
    #[arg(long, value_name = "MS", requires = "partner_wait", value_parser = crate::app::parse::partner_ms)]
    pub partner_reach: Option<u64>,
    /// How many mice share the cage (1 to 5), as the rig config's `[mice] count`: with more
    /// than one, each is found, numbered and posed on its own, a row per pair and mouse.
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = crate::app::parse::mice, allow_negative_numbers = true)]
    pub mice: usize,
    /// Body-forest worker threads (0: one per core).
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u32).range(0..=64))]
    pub workers: u32,
    /// Draw every N-th frame (depth image with the skeleton, bottom view with the paws, side
    /// view) into DIR/overlays/.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub overlays: Option<u64>,
    /// A rig calibration (from `calibrate extrinsics`) to use instead of the session's own.
    #[arg(long, value_name = "FILE", conflicts_with = "intrinsics")]
    pub calibration: Option<PathBuf>,
    /// The depth camera's intrinsics (from `calibrate intrinsics`) for a recording without a
    /// rig calibration; by default the camera its metadata names, or the one of its frame
    /// size (nominal values).
    #[arg(long, value_name = "FILE")]
    pub intrinsics: Option<PathBuf>,
    /// A PNG mask of the arena, one pixel per depth pixel (non-black = inside), instead of
    /// the arena found automatically; the floor is fitted inside it.
    #[arg(long, value_name = "FILE")]
    pub roi: Option<PathBuf>,
    /// Print the summary as one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Replace the output directory if it is not empty.
    #[arg(long)]
    pub force: bool,
}

/// `mousepose replay`: one session, or several (or a pattern) as a batch.
pub fn command(args: &ReplayArgs) -> Outcome {
    if is_batch(&args.sessions) {
        return replay_many(args);
    }
    let session = args.sessions.first().cloned().unwrap_or_default();
    if args.mice > 1 && args.lsl.is_some() {
        return Err(Failure::usage(anyhow::anyhow!(
            "--lsl offers one mouse's stream: with --mice, take the poses from --stream or poses.csv"
        )));
    }
    let options = ReplayOptions {
        stream: args.stream.clone().map(|endpoint| StreamConfig {
            host_clock: "recording",
            lead_ns: args.lead,
            ..StreamConfig::at(endpoint)
        }),
        lsl: args.lsl.as_deref().map(|name| LslConfig {
            live_clock: false,
            lead_ns: args.lead,
            ..LslConfig::named(name)
        }),
        lead_ns: args.lead,
        partner_wait: args.partner_wait.map(|wait| (wait, args.partner_reach)),
        mice: args.mice,
        session: session.clone(),
        out: args.out.clone(),
        models: args.models.clone(),
        realtime: args.realtime,
        workers: args.workers as usize,
        overlays: args.overlays,
        calibration: args.calibration.clone(),
        intrinsics: args.intrinsics.clone(),
        roi: args.roi.clone(),
        force: args.force,
    };
    let interrupt = Interrupt::install().map_err(ReplayError::Signals)?;
    // Rows written against the recording's depth frames (about one row per frame).
    let bar = bar(0, "replay");
    let result = replay_with(&options, &interrupt, |rows, total| {
        bar.set_length(total.max(rows));
        bar.set_position(rows);
    });
    bar.finish_and_clear();
    let summary = result.map_err(|e| Failure::classed(e.is_usage(), e).context(format!("replaying {session:?}")))?;
    if args.json {
        return Ok(print_json(&summary)?);
    }
    Ok(print(&summary_text(&summary, &args.out))?)
}

/// `mousepose replay` with several sessions or a pattern.
fn replay_many(args: &ReplayArgs) -> Outcome {
    if args.realtime
        || args.overlays.is_some()
        || args.stream.is_some()
        || args.lsl.is_some()
        || args.lead.is_some()
        || args.partner_wait.is_some()
        || args.mice > 1
    {
        return Err(Failure::usage(anyhow::anyhow!(
            "--realtime, --overlays, --stream, --lsl, --lead, --partner-wait and --mice are for one session, not a batch"
        )));
    }
    let options = BatchOptions {
        models: args.models.clone(),
        workers: args.workers as usize,
        calibration: args.calibration.clone(),
        force: args.force,
    };
    show_batch(
        &batch(&args.sessions, &args.out, &options, None, &Bars::default())?,
        args.json,
    )
}
