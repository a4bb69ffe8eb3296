//! `mousepose bench`: the speed of mousepose's parts on this machine; the work is
//! [`crate::engine::bench`].

use crate::app::Outcome;
use crate::app::output::{print, print_json};
use crate::engine::bench::run;

#[derive(Debug, clap::Args)]
pub struct BenchArgs {
    /// A short run (a few seconds) instead of the full measurement.
    #[arg(long)]
    quick: bool,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
}

/// `mousepose bench`.
pub fn command(args: &BenchArgs) -> Outcome {
    let report = run(args.quick);
    if args.json {
        return Ok(print_json(&report)?);
    }
    Ok(print(&report.table())?)
}
