//! `mousepose export video RUN --out FILE.mp4`: the arguments, handed to
//! [`crate::engine::export::video`], and what was written printed.

use crate::app::output::print;
use crate::app::progress::Bars;
use crate::engine::Failure;
use crate::engine::export::Run;
use crate::engine::export::video::{VideoExport, VideoOptions};
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct VideoArgs {
    /// The run: a replay's output directory (or a daemon's chunk).
    #[arg(value_name = "RUN")]
    pub run: PathBuf,
    /// The MP4 file to write.
    #[arg(long, value_name = "FILE.mp4")]
    pub out: PathBuf,
    /// The session the run was made from, when its summary does not name it (or it moved).
    #[arg(long, value_name = "DIR")]
    pub session: Option<PathBuf>,
    /// Start this many seconds after the first frame.
    #[arg(long, value_name = "S", value_parser = parse_offset, allow_negative_numbers = true)]
    pub from: Option<f64>,
    /// End this many seconds after the first frame.
    #[arg(long, value_name = "S", value_parser = parse_offset, allow_negative_numbers = true)]
    pub to: Option<f64>,
    /// H.264 quality, 0 (lossless) to 51 (worst); 23 is x264's default.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(0..=51))]
    pub crf: u32,
    /// Replace the file if it exists.
    #[arg(long)]
    pub force: bool,
    /// Print what was written as one JSON object (`out`, `frames`, `width`, `height`).
    #[arg(long)]
    pub json: bool,
}

fn parse_offset(s: &str) -> Result<f64, String> {
    crate::app::parse::ranged(s, "a number of seconds", 0.0, 1e7)
}

/// `mousepose export video`.
pub fn command(args: &VideoArgs) -> crate::app::Outcome {
    let run = Run::open(&args.run, args.session.as_deref()).map_err(Failure::usage)?;
    let v = crate::engine::export::video::video(
        &VideoOptions {
            run,
            out: args.out.clone(),
            from_s: args.from,
            to_s: args.to,
            crf: args.crf,
            force: args.force,
        },
        &Bars::default(),
    )?;
    if args.json {
        #[derive(serde::Serialize)]
        struct Written<'a> {
            out: &'a std::path::Path,
            #[serde(flatten)]
            video: VideoExport,
        }
        return Ok(crate::app::output::print_json(&Written {
            out: &args.out,
            video: v,
        })?);
    }
    let mut text = format!(
        "{} frames of {}x{} over {:.3} s (the cameras' times) to {:?}",
        v.frames,
        v.width,
        v.height,
        v.duration_us as f64 / 1e6,
        args.out
    );
    if v.rows_without_frames > 0 {
        text.push_str(&format!(
            "; {} rows without their depth frame in the session left out",
            v.rows_without_frames
        ));
    }
    text.push('\n');
    Ok(print(&text)?)
}
