//! The command line: one file per command, each with its arguments (clap) and a thin
//! `command` that turns them into an engine's options, calls the engine (`crate::engine`),
//! and prints its summary ([`output`]); flag values are checked by [`parse`]. This file holds
//! the command table, the dispatch, logging, and the one mapping of an engine's [`Failure`]
//! to an exit code. The only place that knows clap and exit codes; `main.rs` only calls
//! [`main`]. No command file imports another (`tests/layers.rs`).

pub mod adapt;
pub mod batch;
pub mod bench;
pub mod calibrate;
pub mod detect;
pub mod devices;
pub mod eval;
pub mod experiment;
pub mod export;
pub mod listen;
pub mod output;
pub mod parse;
pub mod progress;
pub mod record;
pub mod replay;
pub mod report;
pub mod run;
pub mod status;
pub mod synth;
pub mod train;

use crate::engine::Failure;
use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Debug, Parser)]
#[command(
    name = "mousepose",
    version,
    about = "3D pose of a lab mouse from a top depth camera and a bottom colour camera"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Render synthetic training data and sessions.
    #[command(subcommand)]
    Synth(synth::SynthCommand),
    /// Train a forest or the paw cascade on synthetic datasets.
    Train(train::TrainArgs),
    /// Evaluate a trained model on a held-back dataset.
    Eval(eval::EvalArgs),
    /// Fit the body forest and the orientation model to a lab's own mice, from its
    /// unlabelled recordings, into a models directory of their own.
    Adapt(adapt::AdaptArgs),
    /// Reproducible experiments from the paper.
    #[command(subcommand)]
    Experiment(experiment::ExperimentCommand),
    /// Measure the speed of mousepose's parts on this machine.
    Bench(bench::BenchArgs),
    /// Run a recorded or synthetic session through the pipeline: poses.csv and summary.json.
    Replay(replay::ReplayArgs),
    /// Record the rig's cameras to a session (lossless), until --seconds or Ctrl-C/SIGTERM.
    Record(record::RecordArgs),
    /// The daemon: capture, process and record the rig's cameras, through camera faults,
    /// until SIGTERM.
    Run(run::RunArgs),
    /// The running daemon's status (cameras, poses, latency, recording), from its HTTP server.
    Status(status::StatusArgs),
    /// Print the live pose stream of a running daemon (poses and events), as they come.
    Listen(listen::ListenArgs),
    /// List the cameras each backend sees (GigE cameras only at configured addresses).
    Devices(devices::DevicesArgs),
    /// Calibrate the cameras: intrinsics of each, then the rig against a board on the glass.
    #[command(subcommand)]
    Calibrate(calibrate::CalibrateCommand),
    /// A run's behaviour and gait as an HTML page with PNG charts and CSV tables.
    Report(report::ReportArgs),
    /// Replay many sessions, here or as a Slurm job array, with one table for all.
    Batch(batch::BatchArgs),
    /// Export a session or a run: MoSeq layout, or a video with the skeleton drawn.
    #[command(subcommand)]
    Export(export::ExportCommand),
    /// Run a detector on single images: the paw cascade on bottom views.
    #[command(subcommand)]
    Detect(detect::DetectCommand),
}

/// What `train` and `eval` work on (the command line's [`crate::engine::train::ModelTarget`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ModelTarget {
    /// The body forest: joints 1-12 from the top depth image.
    Body,
    /// The part forest: six body-part labels per depth pixel.
    Parts,
    /// The paw detector: a boosted cascade of Haar features on the bottom colour view,
    /// stored as OpenCV cascade XML.
    Paws,
    /// Which end of the mouse is its head from the shape of its body seen from above: a
    /// logistic model on the silhouette and height profile along the body, learnt from the
    /// dataset's mice with their tails hidden and shown (JSON, a few KB).
    Orientation,
}

impl From<ModelTarget> for crate::engine::train::ModelTarget {
    fn from(target: ModelTarget) -> Self {
        match target {
            ModelTarget::Body => Self::Body,
            ModelTarget::Parts => Self::Parts,
            ModelTarget::Paws => Self::Paws,
            ModelTarget::Orientation => Self::Orientation,
        }
    }
}

/// What a command returns.
pub type Outcome = Result<(), Failure>;

/// The exit code of a failed command: 1 when what the user asked for cannot work, 2 when the
/// work itself failed.
fn exit_code(failure: &Failure) -> u8 {
    if failure.is_usage() { 1 } else { 2 }
}

/// The levels a `RUST_LOG` directive may name.
const LOG_LEVELS: [&str; 6] = ["off", "error", "warn", "info", "debug", "trace"];

/// The log filter of `RUST_LOG` (`info` when unset or empty): comma-separated directives,
/// each a level, a module of mousepose (`mousepose::runtime`), or `target=level`. A word that
/// is none of these (a misspelt level) is refused rather than read as a target that never
/// logs.
///
/// # Errors
/// One sentence naming the directive that is wrong.
fn log_filter(value: Option<&str>) -> Result<tracing_subscriber::EnvFilter, String> {
    let Some(value) = value.map(str::trim).filter(|v| !v.is_empty()) else {
        return Ok(tracing_subscriber::EnvFilter::new("info"));
    };
    let levels = LOG_LEVELS.join(", ");
    for directive in value.split(',').map(str::trim).filter(|d| !d.is_empty()) {
        let bare = !directive.contains(['=', '[']);
        let ours = directive == "mousepose" || directive.starts_with("mousepose::");
        if bare && !ours && !LOG_LEVELS.contains(&directive.to_ascii_lowercase().as_str()) {
            return Err(format!(
                "RUST_LOG={value:?} is not a log filter: {directive:?} is neither a level ({levels}) nor target=level"
            ));
        }
    }
    tracing_subscriber::EnvFilter::builder()
        .with_regex(false)
        .parse(value)
        .map_err(|e| format!("RUST_LOG={value:?} is not a log filter ({e}); use a level ({levels}) or target=level"))
}

/// Sets up logging to stderr: plain lines for journald under systemd, with colours on a
/// terminal; `RUST_LOG` picks the level (default `info`).
///
/// # Errors
/// `RUST_LOG` is set but not a log filter.
fn init_logging() -> Result<(), String> {
    use tracing_subscriber::layer::SubscriberExt as _;
    use tracing_subscriber::util::SubscriberInitExt as _;
    let journald = std::env::var_os("JOURNAL_STREAM").is_some();
    let value = std::env::var_os("RUST_LOG").map(|v| v.to_string_lossy().into_owned());
    let filter = log_filter(value.as_deref())?;
    // The last events also go to the daemon's live page.
    let events = crate::runtime::status::events::EventLayer(crate::runtime::status::events::EventLog::global());
    let registry = tracing_subscriber::registry().with(filter).with(events);
    if journald {
        // Under systemd: structured events straight to the journal (fields kept), falling
        // back to plain lines on stderr (which the journal takes too) without a journal socket.
        if let Ok(layer) = tracing_journald::layer() {
            drop(registry.with(layer).try_init());
            return Ok(());
        }
    }
    let fmt = tracing_subscriber::fmt::layer()
        .with_writer(std::io::stderr)
        .with_target(false);
    let result = if journald {
        registry.with(fmt.with_ansi(false).without_time()).try_init()
    } else {
        registry
            .with(fmt.with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr())))
            .try_init()
    };
    // A subscriber installed already (in tests) is fine.
    drop(result);
    Ok(())
}

/// Runs the command line and returns the process's exit code: 0 on success, 1 for bad
/// arguments or configuration, 2 when the work itself failed.
pub fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            let code = if e.use_stderr() { 1 } else { 0 };
            // Printing help or an argument error; nothing more to say if stdout is gone.
            let _ = e.print();
            return ExitCode::from(code);
        }
    };
    if let Err(e) = init_logging() {
        eprintln!("error: {e}");
        return ExitCode::from(1);
    }
    match dispatch(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(failure) => {
            eprintln!("error: {:#}", failure.error());
            ExitCode::from(exit_code(&failure))
        }
    }
}

/// Hands the command line to its command.
fn dispatch(cli: Cli) -> Outcome {
    match cli.command {
        Command::Synth(command) => synth::command(command),
        Command::Train(args) => train::command(&args),
        Command::Eval(args) => eval::command(&args),
        Command::Adapt(args) => adapt::command(&args),
        Command::Experiment(command) => experiment::command(&command),
        Command::Bench(args) => bench::command(&args),
        Command::Replay(args) => replay::command(&args),
        Command::Record(args) => record::command(&args),
        Command::Run(args) => run::command(&args),
        Command::Status(args) => status::command(&args),
        Command::Listen(args) => listen::command(&args),
        Command::Devices(args) => devices::command(&args),
        Command::Calibrate(command) => calibrate::command(&command),
        Command::Export(command) => export::command(&command),
        Command::Batch(args) => batch::command(&args),
        Command::Report(args) => report::command(&args),
        Command::Detect(command) => detect::command(&command),
    }
}

/// The command line's definition: every command, flag and its help (for tests and tools).
pub fn cli() -> clap::Command {
    <Cli as clap::CommandFactory>::command()
}

#[cfg(test)]
mod tests {
    use super::log_filter;

    #[test]
    fn rust_log_takes_levels_modules_and_targets_and_refuses_the_rest() {
        for good in [
            "debug",
            "WARN",
            "info,mousepose::runtime=debug",
            "mousepose",
            "axum=warn",
            "",
        ] {
            assert!(log_filter(Some(good)).is_ok(), "{good}");
        }
        assert!(log_filter(None).is_ok());
        for bad in ["verbose", "debg", "info,loud", "mousepose=loud", "x=1=2"] {
            let e = log_filter(Some(bad)).expect_err(bad);
            assert!(e.starts_with(&format!("RUST_LOG={bad:?} is not a log filter")), "{e}");
            assert!(!e.contains('\n'), "{e}");
        }
    }
}
