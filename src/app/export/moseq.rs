//! `mousepose export moseq SESSION --out DIR`: the arguments, handed to
//! [`crate::engine::export::moseq`], and what was written printed.

use crate::app::output::print;
use crate::app::progress::Bars;
use crate::engine::export::moseq::{COLOR_AVI, MoseqOptions};
use crate::runtime::recording::moseq::DEPTH_AVI;
use clap::Args;
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct MoseqArgs {
    /// The session (or a run whose summary names it).
    #[arg(value_name = "SESSION")]
    pub session: PathBuf,
    /// The directory to write.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// `SubjectName` in metadata.json (default: "unknown").
    #[arg(long, value_name = "NAME")]
    pub subject: Option<String>,
    /// `SessionName` in metadata.json (default: the session directory's name).
    #[arg(long, value_name = "NAME")]
    pub session_name: Option<String>,
    /// Replace the output directory if it is not empty.
    #[arg(long)]
    pub force: bool,
    /// Print what was written as one JSON object (`out`, `depth_frames`, `color_frames`,
    /// `skipped_frames`, `millimetres`).
    #[arg(long)]
    pub json: bool,
}

/// `mousepose export moseq`.
pub fn command(args: &MoseqArgs) -> crate::app::Outcome {
    let e = crate::engine::export::moseq::moseq(
        &MoseqOptions {
            session: args.session.clone(),
            out: args.out.clone(),
            subject: args.subject.clone(),
            session_name: args.session_name.clone(),
            force: args.force,
        },
        &Bars::default(),
    )?;
    if args.json {
        return Ok(crate::app::output::print_json(&e)?);
    }
    let mut text = format!(
        "{} depth frames to {:?}, {} colour frames to {:?}",
        e.depth_frames,
        e.out.join(DEPTH_AVI),
        e.color_frames,
        e.out.join(COLOR_AVI)
    );
    if e.skipped_frames > 0 {
        let _ = write!(text, "; {} damaged frames left out", e.skipped_frames);
    }
    text.push('\n');
    Ok(print(&text)?)
}
