//! `mousepose eval body|parts|paws`: the arguments, handed to [`crate::engine::eval`], and the
//! figures printed.

use crate::app::ModelTarget;
use crate::app::output::{print, print_json};
use crate::engine::eval::EvalOptions;
use clap::Args;
use std::path::PathBuf;

#[derive(Debug, Args)]
pub struct EvalArgs {
    /// Which model.
    #[arg(value_enum)]
    pub target: ModelTarget,
    /// The model file.
    #[arg(long, value_name = "FILE")]
    pub model: PathBuf,
    /// The held-back test dataset.
    #[arg(long, value_name = "DIR")]
    pub data: PathBuf,
    /// Write tables and PNG charts into this directory.
    #[arg(long, value_name = "DIR")]
    pub report: Option<PathBuf>,
    /// A baseline model to compare against in the report (body).
    #[arg(long, value_name = "FILE")]
    pub baseline: Option<PathBuf>,
    /// See the bottom views as a colour camera binned by this factor sees them (1, 2 or 4;
    /// paws).
    #[arg(long, value_name = "K", default_value_t = 1, value_parser = crate::app::parse::binning)]
    pub color_binning: u32,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// `mousepose eval body|parts|paws`.
pub fn run(args: &EvalArgs) -> crate::app::Outcome {
    let summary = crate::engine::eval::eval(&EvalOptions {
        target: args.target.into(),
        model: args.model.clone(),
        data: args.data.clone(),
        report: args.report.clone(),
        baseline: args.baseline.clone(),
        color_binning: args.color_binning,
    })?;
    if args.json {
        return Ok(print_json(&summary)?);
    }
    Ok(print(&summary.text())?)
}
