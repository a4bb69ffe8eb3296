//! The command line: argument parsing and the commands themselves. `main.rs` only calls
//! [`main`] and turns its result into an exit code.

pub mod bench;
pub mod calibrate;
pub mod chart;
pub mod commands;
pub mod progress;

use crate::core::frame::PixelFormat;
use crate::core::noise::DepthNoise;
use crate::core::noise::NoiseModel;
use crate::io::output::Staging;
use crate::synth::dataset::{DatasetSpec, write_dataset};
use crate::synth::session::{SessionSpec, write_session};
use anyhow::{Context, Result};
use clap::{Args, Parser, Subcommand};
use std::io::Write;
use std::path::PathBuf;
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
    Synth(SynthCommand),
    /// Train a forest or the paw cascade on synthetic datasets.
    Train(TrainArgs),
    /// Evaluate a trained model on a held-back dataset.
    Eval(EvalArgs),
    /// Reproducible experiments from the paper.
    #[command(subcommand)]
    Experiment(ExperimentCommand),
    /// Measure the speed of mousepose's parts on this machine.
    Bench(BenchArgs),
    /// Run a recorded or synthetic session through the pipeline: poses.csv and summary.json.
    Replay(ReplayArgs),
    /// Record the rig's cameras to a session (lossless), until --seconds or Ctrl-C/SIGTERM.
    Record(RecordArgs),
    /// List the cameras each backend sees (GigE cameras only at configured addresses).
    Devices(DevicesArgs),
    /// Calibrate the cameras: intrinsics of each, then the rig against a board on the glass.
    #[command(subcommand)]
    Calibrate(calibrate::CalibrateCommand),
}

#[derive(Debug, Args)]
pub struct RecordArgs {
    /// The rig configuration.
    #[arg(long, value_name = "FILE")]
    pub config: PathBuf,
    /// The session directory to write.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Stop after this many seconds (otherwise at Ctrl-C or SIGTERM).
    #[arg(long, value_name = "N", value_parser = parse_seconds, allow_negative_numbers = true)]
    pub seconds: Option<f64>,
    /// Print the summary as one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Replace the output directory if it is not empty.
    #[arg(long)]
    pub force: bool,
}

#[derive(Debug, Args)]
pub struct DevicesArgs {
    /// A rig configuration: GigE Vision cameras are probed at its addresses.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// The session directory (written by `record`, `run` or `synth session`).
    #[arg(value_name = "SESSION")]
    pub session: PathBuf,
    /// The directory to write poses.csv and summary.json into.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// The models directory (body.forest); the bundled models by default.
    #[arg(long, value_name = "DIR")]
    pub models: Option<PathBuf>,
    /// Deliver the frames at the pace they were recorded instead of as fast as possible.
    #[arg(long)]
    pub realtime: bool,
    /// Body-forest worker threads (0: one per core).
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u32).range(0..=64))]
    pub workers: u32,
    /// Draw every N-th frame (depth image with the skeleton, bottom view with the paws, side
    /// view) into DIR/overlays/.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub overlays: Option<u64>,
    /// A rig calibration (from `calibrate extrinsics`) to use instead of the session's own.
    #[arg(long, value_name = "FILE")]
    pub calibration: Option<PathBuf>,
    /// Print the summary as one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Replace the output directory if it is not empty.
    #[arg(long)]
    pub force: bool,
}

/// What `train` and `eval` work on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ModelTarget {
    /// The body forest: joints 1-12 from the top depth image.
    Body,
    /// The part forest: six body-part labels per depth pixel.
    Parts,
    /// The paw detector: a boosted cascade of Haar features on the bottom colour view,
    /// stored as OpenCV cascade XML.
    Paws,
}

#[derive(Debug, Args)]
pub struct TrainArgs {
    /// Which model.
    #[arg(value_enum)]
    pub target: ModelTarget,
    /// The training dataset (D_t).
    #[arg(long, value_name = "DIR")]
    pub data: PathBuf,
    /// The model file to write.
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Trees in the forest.
    #[arg(long, default_value_t = 7, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub trees: u32,
    /// Maximum tree depth (L).
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(1..=40))]
    pub depth: u32,
    /// Random tests per split node (m).
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u32).range(1..=10_000))]
    pub tests: u32,
    /// Fewest samples to split a node (l_n).
    #[arg(long, default_value_t = 60, value_parser = clap::value_parser!(u32).range(2..=1_000_000))]
    pub leaf: u32,
    /// A second dataset (D_d) for the paper's discriminative training of the trained forest.
    #[arg(long, value_name = "DIR")]
    pub discriminative: Option<PathBuf>,
    /// Refine this trained baseline (trained on --data) instead of training one first.
    #[arg(long, value_name = "FILE", requires = "discriminative")]
    pub from: Option<PathBuf>,
    /// Passes of discriminative training.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=20))]
    pub iterations: u32,
    /// Tree level where discriminative training starts.
    #[arg(long, default_value_t = 0)]
    pub start_level: u32,
    /// Fraction of D_d each tree sees (D'_d); it should hold about as many pixels as D_t, or
    /// the shrink rule coarsens the trees.
    #[arg(long, default_value_t = 0.5, value_parser = parse_subset)]
    pub subset: f64,
    /// In discriminative training, refit the leaves that stay leaves to D'_d instead of
    /// keeping what D_t taught them.
    #[arg(long)]
    pub refit_leaves: bool,
    /// Mouse pixels drawn per training image.
    #[arg(long, default_value_t = 150, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub pixels: u32,
    /// Seed of the pixel draws and the random tests (paws: of the augmentation and the
    /// negatives' draws).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Cascade stages at most (paws).
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(1..=50))]
    pub stages: u32,
    /// Replace the model file if it exists.
    #[arg(long)]
    pub force: bool,
}

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
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Subcommand)]
enum ExperimentCommand {
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

#[derive(Debug, Subcommand)]
enum SynthCommand {
    /// A training or test set of independent rendered instants.
    Dataset(DatasetArgs),
    /// A continuous behaviour sequence written as a recorded session.
    Session(SessionArgs),
    /// Rendered chessboard views of both cameras, for testing calibration end to end.
    Chessboard(calibrate::ChessboardArgs),
}

#[derive(Debug, Args)]
struct NoiseArgs {
    /// Gaussian depth noise, standard deviation in millimetres.
    #[arg(long = "noise-mm", value_name = "SIGMA", default_value_t = 0.0, value_parser = parse_noise_mm, allow_negative_numbers = true)]
    noise_mm: f64,
}

#[derive(Debug, Args)]
struct DatasetArgs {
    /// The dataset directory to create.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Number of images.
    #[arg(long, value_name = "N", value_parser = parse_images, allow_negative_numbers = true)]
    images: u64,
    /// Seed of the random poses, placements and noise.
    #[arg(long, value_name = "S", default_value_t = 0)]
    seed: u64,
    #[command(flatten)]
    noise: NoiseArgs,
    /// Depth camera noise model: none, structured-light or tof.
    #[arg(long = "noise-model", value_name = "MODEL", default_value = "none")]
    noise_model: NoiseModel,
    /// Leave out the bottom colour views (smaller and faster, for body and part training).
    #[arg(long)]
    no_bottom: bool,
    /// Replace the output directory if it is not empty.
    #[arg(long)]
    force: bool,
}

#[derive(Debug, Args)]
struct SessionArgs {
    /// The session directory to create.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Length of the session.
    #[arg(long, value_name = "N", value_parser = parse_seconds, allow_negative_numbers = true)]
    seconds: f64,
    /// Frame rate of both cameras.
    #[arg(long, value_name = "FPS", default_value_t = 30.0, value_parser = parse_fps, allow_negative_numbers = true)]
    fps: f64,
    /// Seed of the behaviour sequence, the clocks and the noise.
    #[arg(long, value_name = "S", default_value_t = 0)]
    seed: u64,
    #[command(flatten)]
    noise: NoiseArgs,
    /// Depth camera noise model: none, structured-light or tof.
    #[arg(long = "noise-model", value_name = "MODEL", default_value = "structured-light")]
    noise_model: NoiseModel,
    /// Bin the colour camera's 1280x1024 sensor by this factor (1, 2 or 4).
    #[arg(long, value_name = "K", default_value_t = 1, value_parser = parse_binning)]
    color_binning: u32,
    /// Depth camera only (the paper's single-depth-image mode).
    #[arg(long)]
    no_color: bool,
    /// Replace the output directory if it is not empty.
    #[arg(long)]
    force: bool,
}

#[derive(Debug, Args)]
struct BenchArgs {
    /// A short run (a few seconds) instead of the full measurement.
    #[arg(long)]
    quick: bool,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
}

fn parse_ranged<T>(s: &str, what: &str, lo: T, hi: T) -> Result<T, String>
where
    T: std::str::FromStr + PartialOrd + std::fmt::Display + Copy,
{
    let v: T = s
        .trim()
        .parse()
        .map_err(|_| format!("expected {what} from {lo} to {hi}, got {s:?}"))?;
    if v < lo || v > hi {
        return Err(format!("expected {what} from {lo} to {hi}, got {s}"));
    }
    Ok(v)
}

fn parse_images(s: &str) -> Result<u64, String> {
    parse_ranged(s, "a whole number of images", 1, 10_000_000)
}

fn parse_seconds(s: &str) -> Result<f64, String> {
    let v = parse_ranged(s, "a number of seconds", 0.0, 86_400.0)?;
    if v <= 0.0 {
        return Err(format!("expected a number of seconds above 0, got {s}"));
    }
    Ok(v)
}

fn parse_subset(s: &str) -> Result<f64, String> {
    let v = parse_ranged(s, "a fraction of the data set", 0.0, 1.0)?;
    if v <= 0.0 {
        return Err(format!("expected a fraction of the data set above 0, got {s}"));
    }
    Ok(v)
}

fn parse_fps(s: &str) -> Result<f64, String> {
    parse_ranged(s, "a frame rate", 1.0, 1000.0)
}

fn parse_noise_mm(s: &str) -> Result<f64, String> {
    parse_ranged(s, "a noise level in millimetres", 0.0, 100.0)
}

fn parse_binning(s: &str) -> Result<u32, String> {
    match s.trim() {
        "1" => Ok(1),
        "2" => Ok(2),
        "4" => Ok(4),
        other => Err(format!("expected a binning factor of 1, 2 or 4, got {other:?}")),
    }
}

/// Sets up logging to stderr: plain lines for journald under systemd, with colours on a
/// terminal; `RUST_LOG` picks the level (default `info`).
fn init_logging() {
    let journald = std::env::var_os("JOURNAL_STREAM").is_some();
    let filter = tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into());
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false);
    let result = if journald {
        builder.with_ansi(false).without_time().try_init()
    } else {
        builder
            .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
            .try_init()
    };
    // A subscriber installed already (in tests) is fine.
    drop(result);
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
    init_logging();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(exit_code(&e))
        }
    }
}

/// 1 when the error is about what the user asked for, 2 when the work failed.
fn exit_code(e: &anyhow::Error) -> u8 {
    let usage = e.chain().any(|c| {
        matches!(
            c.downcast_ref::<crate::io::output::OutputError>(),
            Some(crate::io::output::OutputError::NotEmpty(_) | crate::io::output::OutputError::NotADirectory(_))
        ) || c.is::<commands::Exists>()
            || c.is::<crate::runtime::config::ConfigError>()
            || c.is::<calibrate::UsageError>()
            || c.downcast_ref::<crate::vision::calibrate::CalibrationError>()
                .is_some_and(crate::vision::calibrate::CalibrationError::is_input_problem)
            || matches!(
                c.downcast_ref::<crate::runtime::record::RecordError>(),
                Some(
                    crate::runtime::record::RecordError::NotEmpty(_)
                        | crate::runtime::record::RecordError::Calibration(_)
                )
            )
    });
    if usage { 1 } else { 2 }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Synth(SynthCommand::Dataset(args)) => synth_dataset(&args),
        Command::Synth(SynthCommand::Session(args)) => synth_session(&args),
        Command::Train(args) => commands::train(&args),
        Command::Eval(args) => commands::eval(&args),
        Command::Experiment(ExperimentCommand::Gauss2d(args)) => commands::gauss2d(&args),
        Command::Bench(args) => run_bench(&args),
        Command::Replay(args) => commands::replay(&args),
        Command::Record(args) => commands::record(&args),
        Command::Devices(args) => commands::devices(&args),
        Command::Calibrate(command) => calibrate::run(&command),
        Command::Synth(SynthCommand::Chessboard(args)) => calibrate::synth_chessboard(&args),
    }
}

fn synth_dataset(args: &DatasetArgs) -> Result<()> {
    let staging = Staging::new(&args.out, args.force)?;
    let spec = DatasetSpec {
        count: args.images,
        seed: args.seed,
        noise: DepthNoise {
            model: args.noise_model,
            gaussian_mm: args.noise.noise_mm,
        },
        bottom_views: !args.no_bottom,
    };
    let bar = progress::bar(spec.count, "rendering");
    let rig = crate::core::geometry::Rig::default_rig();
    write_dataset(staging.path(), &rig, &spec, |done| bar.set_position(done))
        .with_context(|| format!("writing dataset {:?}", args.out))?;
    bar.finish_and_clear();
    let out = staging.commit()?;
    tracing::info!(message = "Dataset written.", path = %out.display(), images = spec.count);
    Ok(())
}

fn synth_session(args: &SessionArgs) -> Result<()> {
    let staging = Staging::new(&args.out, args.force)?;
    let spec = SessionSpec {
        seconds: args.seconds,
        fps: args.fps,
        seed: args.seed,
        noise: DepthNoise {
            model: args.noise_model,
            gaussian_mm: args.noise.noise_mm,
        },
        color_binning: args.color_binning,
        color_format: PixelFormat::BayerRg8,
        color: !args.no_color,
    };
    let bar = progress::bar(0, "rendering");
    let summary = write_session(staging.path(), &spec, |done, total| {
        bar.set_length(total);
        bar.set_position(done);
    })
    .with_context(|| format!("writing session {:?}", args.out))?;
    bar.finish_and_clear();
    let out = staging.commit()?;
    tracing::info!(
        message = "Session written.",
        path = %out.display(),
        depth_frames = summary.depth_frames,
        color_frames = summary.color_frames,
        preview = %out.join(crate::synth::session::PREVIEW_FILE).display(),
    );
    Ok(())
}

fn run_bench(args: &BenchArgs) -> Result<()> {
    let report = bench::run(args.quick);
    let mut stdout = std::io::stdout().lock();
    if args.json {
        writeln!(stdout, "{}", serde_json::to_string_pretty(&report)?)?;
    } else {
        write!(stdout, "{}", report.table())?;
    }
    Ok(())
}
