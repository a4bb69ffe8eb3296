//! `mousepose record`: the rig's cameras to a session; the work is [`crate::engine::record`].

use crate::app::Outcome;
use crate::app::output::{print, print_json};
use crate::engine::Failure;
use crate::engine::record::{RecordOptions, RecordSummary, record_until_signal};
use clap::Args;
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct RecordArgs {
    /// The rig configuration.
    #[arg(long, value_name = "FILE")]
    pub config: PathBuf,
    /// The session directory to write.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Stop after this many seconds (otherwise at Ctrl-C or SIGTERM).
    #[arg(long, value_name = "N", value_parser = crate::app::parse::seconds, allow_negative_numbers = true)]
    pub seconds: Option<f64>,
    /// Print the summary as one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Replace the output directory if it is not empty.
    #[arg(long)]
    pub force: bool,
}

/// `mousepose record`.
pub fn command(args: &RecordArgs) -> Outcome {
    let (summary, unexpected) = record_until_signal(&RecordOptions {
        config: args.config.clone(),
        out: args.out.clone(),
        seconds: args.seconds,
        force: args.force,
    })?;
    if args.json {
        print_json(&summary)?;
    } else {
        print(&summary_text(&summary))?;
    }
    if let Some(why) = unexpected {
        return Err(Failure::classed(false, anyhow::anyhow!(why)));
    }
    let silent = summary.silent_cameras();
    if !silent.is_empty() {
        return Err(Failure::classed(false, anyhow::anyhow!("{}", silent.join("; "))));
    }
    Ok(())
}

/// The summary for a terminal.
fn summary_text(summary: &RecordSummary) -> String {
    let mut text = format!(
        "recorded {:.1} s to {:?}: {} depth frames ({:.1} MB), {} colour frames ({:.1} MB), {:.2} cores\n",
        summary.seconds,
        summary.dir,
        summary.depth_frames,
        summary.depth_bytes as f64 / 1e6,
        summary.color_frames,
        summary.color_bytes as f64 / 1e6,
        summary.cpu_cores
    );
    for (name, c) in &summary.cameras {
        let _ = writeln!(
            text,
            "{name:>6}: captured {}, recorded {}, not recorded {} {:?}, lost before capture {:?}",
            c.captured,
            c.recorded.unwrap_or(0),
            c.not_recorded_total,
            c.not_recorded,
            c.lost_before_capture
        );
    }
    text
}
