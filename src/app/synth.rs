//! `mousepose synth dataset|session|chessboard|moseq`: rendered training data, sessions and
//! recordings. The arguments, handed to [`crate::engine::synth`] (and
//! [`crate::engine::calibrate`] for chessboards).

use crate::app::Outcome;
use crate::app::parse;
use crate::app::progress::Bars;
use crate::core::frame::PixelFormat;
use crate::core::noise::{DepthNoise, NoiseModel};
use crate::engine::calibrate::{self, ChessboardOptions};
use crate::engine::synth::{self as engine, DatasetOptions, MoseqOptions, SessionOptions};
use crate::synth::dataset::DatasetSpec;
use crate::synth::moseq::MoseqSpec;
use crate::synth::session::{MOST_MICE, SessionSpec, TailLook};
use clap::{Args, Subcommand};
use std::path::PathBuf;

#[derive(Debug, Subcommand)]
pub enum SynthCommand {
    /// A training or test set of independent rendered instants.
    Dataset(DatasetArgs),
    /// A continuous behaviour sequence written as a recorded session.
    Session(SessionArgs),
    /// Rendered chessboard views of both cameras, for testing calibration end to end.
    Chessboard(ChessboardArgs),
    /// A depth-only recording in MoSeq's layout (depth.dat, depth_ts.txt, metadata.json, and
    /// the true camera as rig.yaml): a session's mouse under a real rig's camera.
    Moseq(MoseqArgs),
}

#[derive(Debug, Args)]
pub struct ChessboardArgs {
    /// The directory to create.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Inner corners of the board, COLSxROWS.
    #[arg(long, default_value = "9x6")]
    pub board: String,
    /// The side of one square, millimetres (40: a 400 x 280 mm board, which poses both cameras
    /// within 0.3 mm; 20 mm squares give about 1 mm).
    #[arg(long = "square-mm", value_name = "S", value_parser = parse::square_mm, allow_negative_numbers = true, default_value_t = 40.0)]
    pub square_mm: f64,
    /// Intrinsics views per camera.
    #[arg(long, value_name = "N", default_value_t = 15, value_parser = clap::value_parser!(u32).range(1..=500))]
    pub views: u32,
    /// Seed of the board poses, lighting and noise.
    #[arg(long, value_name = "S", default_value_t = 0)]
    pub seed: u64,
    /// Bin the colour camera's 1280x1024 sensor by this factor (1, 2 or 4).
    #[arg(long, value_name = "K", default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=4))]
    pub color_binning: u32,
    /// Replace the output directory if it is not empty.
    #[arg(long)]
    pub force: bool,
    /// Print what was written as one JSON object (`out`, `views`).
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Args)]
pub struct MoseqArgs {
    /// The recording directory to create.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Number of depth frames.
    #[arg(long, value_name = "N", default_value_t = 900, value_parser = parse::images, allow_negative_numbers = true)]
    frames: u64,
    /// Frame rate (timestamps in depth_ts.txt).
    #[arg(long, value_name = "FPS", default_value_t = 30.0, value_parser = parse::fps, allow_negative_numbers = true)]
    fps: f64,
    /// Seed of the behaviour sequence (the synthetic session's of the same seed) and the noise.
    #[arg(long, value_name = "S", default_value_t = 0)]
    seed: u64,
    /// Frame size, WIDTHxHEIGHT, one of the depth camera table's (nominal intrinsics).
    #[arg(long, value_name = "WxH", default_value = "512x424", value_parser = parse_size)]
    size: (u32, u32),
    /// The camera's height above the floor (mm).
    #[arg(long, value_name = "MM", default_value_t = 670.0, value_parser = parse_camera_height, allow_negative_numbers = true)]
    camera_height_mm: f64,
    /// The camera's tilt from looking straight down (degrees).
    #[arg(long, value_name = "DEG", default_value_t = 0.0, value_parser = parse_tilt, allow_negative_numbers = true)]
    tilt_deg: f64,
    /// A mouse of this size instead of a standard one drawn at random: every length times
    /// this (the standard mouse: 1). With --girth and --back-height, a known mouse for
    /// checking what `adapt` measures.
    #[arg(long, value_name = "FACTOR", value_parser = parse_build_factor, allow_negative_numbers = true)]
    scale: Option<f64>,
    /// With --scale: the body's width beyond the scale (the standard mouse: 1).
    #[arg(long, value_name = "FACTOR", requires = "scale", default_value_t = 1.0, value_parser = parse_build_factor, allow_negative_numbers = true)]
    girth: f64,
    /// With --scale: the back's height beyond the scale (the standard mouse: 1).
    #[arg(long, value_name = "FACTOR", requires = "scale", default_value_t = 1.0, value_parser = parse_build_factor, allow_negative_numbers = true)]
    back_height: f64,
    #[command(flatten)]
    noise: NoiseArgs,
    /// Depth camera noise model: none, structured-light or tof.
    #[arg(long = "noise-model", value_name = "MODEL", default_value = "tof")]
    noise_model: NoiseModel,
    /// Write the frames as depth.avi (lossless 16-bit FFV1, as MoSeq compresses a recording;
    /// about a fifth of depth.dat's size) instead of depth.dat.
    #[arg(long)]
    video: bool,
    /// Replace the output directory if it is not empty.
    #[arg(long)]
    force: bool,
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let bad = || format!("expected a frame size WIDTHxHEIGHT such as 512x424, got {s}");
    let (w, h) = s.trim().split_once('x').ok_or_else(bad)?;
    let w: u32 = w.trim().parse().map_err(|_| bad())?;
    let h: u32 = h.trim().parse().map_err(|_| bad())?;
    if w == 0 || h == 0 {
        return Err(bad());
    }
    Ok((w, h))
}

fn parse_camera_height(s: &str) -> Result<f64, String> {
    parse::ranged(s, "a camera height in millimetres", 300.0, 2000.0)
}

fn parse_build_factor(s: &str) -> Result<f64, String> {
    parse::ranged(s, "a factor of the standard mouse's size", 0.5, 2.0)
}

fn parse_tilt(s: &str) -> Result<f64, String> {
    parse::ranged(s, "a tilt in degrees", 0.0, 30.0)
}

#[derive(Debug, Args)]
pub struct NoiseArgs {
    /// Gaussian depth noise, standard deviation in millimetres.
    #[arg(long = "noise-mm", value_name = "SIGMA", default_value_t = 0.0, value_parser = parse::noise_mm, allow_negative_numbers = true)]
    noise_mm: f64,
}

#[derive(Debug, Args)]
pub struct DatasetArgs {
    /// The dataset directory to create.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Number of images.
    #[arg(long, value_name = "N", value_parser = parse::images, allow_negative_numbers = true)]
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
    /// Draw into the bottom views what real ones show besides the paws: glare at the glass's
    /// edge, pale spots and scratches on the glass, a pale patch of belly fur (the paw
    /// detector's hard negatives; their boxes are stored with the views).
    #[arg(long, conflicts_with = "no_bottom")]
    bottom_clutter: bool,
    /// Print what was written as one JSON object (`out`, `images`).
    #[arg(long)]
    json: bool,
    /// standard: mice in the range the bundled forests were trained on; varied: sizes, body
    /// shapes, backs and tails well outside it (see `synth session --mice`); mixed: every
    /// other image varied.
    #[arg(long, value_name = "KIND", default_value = "standard")]
    mice: crate::synth::Mice,
    /// Replace the output directory if it is not empty.
    #[arg(long)]
    force: bool,
}

#[derive(Debug, Args)]
pub struct SessionArgs {
    /// The session directory to create.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Length of the session.
    #[arg(long, value_name = "N", value_parser = parse::seconds, allow_negative_numbers = true)]
    seconds: f64,
    /// Frame rate of both cameras.
    #[arg(long, value_name = "FPS", default_value_t = 30.0, value_parser = parse::fps, allow_negative_numbers = true)]
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
    #[arg(long, value_name = "K", default_value_t = 1, value_parser = parse::binning)]
    color_binning: u32,
    /// Depth camera only (the paper's single-depth-image mode).
    #[arg(long)]
    no_color: bool,
    /// Print what was written as one JSON object (`out`, `depth_frames`, `color_frames`,
    /// `preview`).
    #[arg(long)]
    json: bool,
    /// How many mice share the cage (1 to 5; the others each of a build of its own), or what
    /// the first is like: standard, like the ones the bundled forests were trained on; varied,
    /// sizes, body shapes, backs and tails well outside that range (a stress test); mixed,
    /// varied for odd seeds. Given twice for both, e.g. `--mice 2 --mice varied`.
    #[arg(long, value_name = "N|KIND", value_parser = parse_mice, action = clap::ArgAction::Append, allow_negative_numbers = true)]
    mice: Vec<MiceArg>,
    /// What the mouse does: anything (mixed), stays in place (still: standing, sniffing,
    /// grooming, rearing, bending), or walks (walking).
    #[arg(long, value_name = "mixed|still|walking", default_value = "mixed", value_parser = parse_activity)]
    activity: crate::synth::animate::Activity,
    /// visible: the tail rendered as it is (3-5 mm thick on the floor); hidden: not rendered,
    /// as a depth camera that does not see a 3-5 mm tail shows it; raised: blurred and raised
    /// by mixed pixels, as real Kinects show it (about 6 mm wide, reading 24 mm above the floor
    /// at its base, 10 mm at its tip). The truth keeps its joints.
    #[arg(long, value_name = "visible|hidden|raised", default_value = "visible", value_parser = parse_tail, action = clap::ArgAction::Set)]
    tail: TailLook,
    /// Replace the output directory if it is not empty.
    #[arg(long)]
    force: bool,
}

/// `mousepose synth ...`.
pub fn command(command: SynthCommand) -> Outcome {
    match command {
        SynthCommand::Dataset(args) => synth_dataset(&args),
        SynthCommand::Session(args) => synth_session(&args),
        SynthCommand::Chessboard(args) => synth_chessboard(&args),
        SynthCommand::Moseq(args) => synth_moseq(&args),
    }
}

fn synth_chessboard(args: &ChessboardArgs) -> Outcome {
    let summary = calibrate::synth_chessboard(
        &ChessboardOptions {
            out: args.out.clone(),
            board: args.board.clone(),
            square_mm: args.square_mm,
            views: args.views,
            seed: args.seed,
            color_binning: args.color_binning,
            force: args.force,
        },
        &Bars::default(),
    )?;
    if args.json {
        crate::app::output::print_json(&serde_json::json!({ "out": summary.out, "views": summary.views }))?;
    }
    Ok(())
}

fn synth_moseq(args: &MoseqArgs) -> Outcome {
    let spec = MoseqSpec {
        frames: args.frames,
        fps: args.fps,
        seed: args.seed,
        noise: DepthNoise {
            model: args.noise_model,
            gaussian_mm: args.noise.noise_mm,
        },
        width: args.size.0,
        height: args.size.1,
        camera_height_mm: args.camera_height_mm,
        tilt_deg: args.tilt_deg,
        build: args.scale.map(|scale| crate::synth::Build {
            scale,
            girth: args.girth,
            height: args.back_height,
            tail_shown: 1.0,
        }),
        video: args.video,
    };
    engine::synth_moseq(
        &MoseqOptions {
            out: args.out.clone(),
            spec,
            force: args.force,
        },
        &Bars::default(),
    )?;
    Ok(())
}

fn synth_dataset(args: &DatasetArgs) -> Outcome {
    let spec = DatasetSpec {
        count: args.images,
        seed: args.seed,
        noise: DepthNoise {
            model: args.noise_model,
            gaussian_mm: args.noise.noise_mm,
        },
        bottom_views: !args.no_bottom,
        bottom_clutter: args.bottom_clutter,
        mice: args.mice,
        build: None,
    };
    let summary = engine::synth_dataset(
        &DatasetOptions {
            out: args.out.clone(),
            spec,
            force: args.force,
        },
        &Bars::default(),
    )?;
    if args.json {
        crate::app::output::print_json(&serde_json::json!({ "out": summary.out, "images": summary.images }))?;
    }
    Ok(())
}

fn synth_session(args: &SessionArgs) -> Outcome {
    // `--mice` given as a number, a kind, or both: the last of each counts.
    let (mut kind, mut count) = (crate::synth::Mice::default(), 1);
    for m in &args.mice {
        match *m {
            MiceArg::Kind(k) => kind = k,
            MiceArg::Count(n) => count = n,
        }
    }
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
        mice: kind,
        build: None,
        activity: args.activity,
        tail: args.tail,
        count,
    };
    let summary = engine::synth_session(
        &SessionOptions {
            out: args.out.clone(),
            spec,
            force: args.force,
        },
        &Bars::default(),
    )?;
    if args.json {
        crate::app::output::print_json(&serde_json::json!({
            "out": summary.out,
            "depth_frames": summary.depth_frames,
            "color_frames": summary.color_frames,
            "preview": summary.preview,
        }))?;
    }
    Ok(())
}

/// A value of `synth session --mice`: how many, or what kind.
#[derive(Clone, Copy, Debug)]
enum MiceArg {
    Count(usize),
    Kind(crate::synth::Mice),
}

/// `--mice N|KIND`: a number of mice from 1 to [`MOST_MICE`], or a kind of mice.
fn parse_mice(s: &str) -> Result<MiceArg, String> {
    match s.parse::<i64>() {
        Ok(n) if (1..=MOST_MICE as i64).contains(&n) => Ok(MiceArg::Count(n as usize)),
        Ok(n) => Err(format!("a synthetic session renders 1 to {MOST_MICE} mice, not {n}")),
        Err(_) => s.parse().map(MiceArg::Kind),
    }
}

/// `--tail visible|hidden|raised`: how the depth camera shows the tail.
fn parse_tail(s: &str) -> Result<TailLook, String> {
    match s {
        "visible" => Ok(TailLook::Visible),
        "hidden" => Ok(TailLook::Hidden),
        "raised" => Ok(TailLook::Raised),
        _ => Err(format!("{s:?} is not a tail: visible, hidden or raised")),
    }
}

/// `--activity mixed|still|walking`.
fn parse_activity(s: &str) -> Result<crate::synth::animate::Activity, String> {
    use crate::synth::animate::Activity;
    match s {
        "mixed" => Ok(Activity::Mixed),
        "still" => Ok(Activity::Still),
        "walking" => Ok(Activity::Walking),
        _ => Err(format!("{s:?} is not an activity: mixed, still or walking")),
    }
}
