//! `mousepose run`: the daemon; the work is [`crate::engine::daemon`].

use crate::app::Outcome;
use crate::app::output::{print, print_json};
use crate::engine::Failure;
use crate::engine::daemon::{DaemonOptions, daemon};
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct RunArgs {
    /// The rig configuration.
    #[arg(long, value_name = "FILE")]
    pub config: PathBuf,
    /// Stop after this many seconds (a daemon runs until SIGTERM).
    #[arg(long, value_name = "N", value_parser = crate::app::parse::seconds, allow_negative_numbers = true)]
    pub seconds: Option<f64>,
    /// A session recorded with the cage empty, as the background reference (instead of the
    /// config's `[segment] background`, or of learning the background live).
    #[arg(long, value_name = "DIR")]
    pub background: Option<PathBuf>,
    /// The models directory (as `adapt` writes), instead of the config's `[models] dir` or
    /// the bundled models.
    #[arg(long, value_name = "DIR")]
    pub models: Option<PathBuf>,
    /// Print the final report as one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// `mousepose run`.
pub fn command(args: &RunArgs) -> Outcome {
    let (report, unexpected) = daemon(&DaemonOptions {
        config: args.config.clone(),
        seconds: args.seconds,
        background: args.background.clone(),
        models: args.models.clone(),
    })?;
    if args.json {
        print_json(&report)?;
    } else {
        print(&format!("ran {}", report.text()))?;
    }
    match unexpected {
        Some(why) => Err(Failure::classed(false, anyhow::anyhow!(why))),
        None => Ok(()),
    }
}
