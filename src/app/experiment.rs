//! `mousepose experiment gauss2d`: the arguments, handed to [`crate::engine::experiment`], and
//! the figures printed.

use crate::app::output::{print, print_json};
use crate::app::progress::Bars;
use crate::engine::experiment::{Gauss2dOptions, gauss2d_tables};
use clap::{Args, Subcommand};
use std::path::PathBuf;

#[derive(Debug, Subcommand)]
pub enum ExperimentCommand {
    /// The paper's running example: 2D Gaussians, baseline vs discriminative training.
    Gauss2d(Gauss2dArgs),
}

#[derive(Debug, Args)]
pub struct Gauss2dArgs {
    /// A tenth of the data and shorter sweeps (under a minute).
    #[arg(long)]
    pub quick: bool,
    /// Seed of the Gaussians and all draws.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Write tables and PNG plots of the sweeps into this directory.
    #[arg(long, value_name = "DIR")]
    pub report: Option<PathBuf>,
    /// Print one JSON object instead of tables.
    #[arg(long)]
    pub json: bool,
}

/// `mousepose experiment ...`.
pub fn command(command: &ExperimentCommand) -> crate::app::Outcome {
    match command {
        ExperimentCommand::Gauss2d(args) => gauss2d(args),
    }
}

/// `mousepose experiment gauss2d`.
fn gauss2d(args: &Gauss2dArgs) -> crate::app::Outcome {
    let report = crate::engine::experiment::gauss2d(
        &Gauss2dOptions {
            quick: args.quick,
            seed: args.seed,
            report: args.report.clone(),
        },
        &Bars::default(),
    )?;
    if args.json {
        return Ok(print_json(&report)?);
    }
    Ok(print(&gauss2d_tables(&report))?)
}
