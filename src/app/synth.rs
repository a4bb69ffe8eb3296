//! `mousepose synth dataset|session|chessboard|moseq`: rendered training data, sessions and recordings.

use crate::app::progress;
use crate::app::{Outcome, output_failure};
use crate::app::{parse_binning, parse_fps, parse_images, parse_noise_mm, parse_seconds};
use crate::core::frame::PixelFormat;
use crate::core::noise::{DepthNoise, NoiseModel};
use crate::io::output::Staging;
use crate::synth::dataset::{DatasetSpec, write_dataset};
use crate::synth::moseq::{MoseqSpec, moseq_camera, write_moseq};
use crate::synth::session::{SessionSpec, write_session};
use anyhow::Context as _;
use clap::{Args, Subcommand};
use std::path::PathBuf;

#[derive(Debug, Subcommand)]
pub enum SynthCommand {
    /// A training or test set of independent rendered instants.
    Dataset(DatasetArgs),
    /// A continuous behaviour sequence written as a recorded session.
    Session(SessionArgs),
    /// Rendered chessboard views of both cameras, for testing calibration end to end.
    Chessboard(crate::app::calibrate::ChessboardArgs),
    /// A depth-only recording in MoSeq's layout (depth.dat, depth_ts.txt, metadata.json, and
    /// the true camera as rig.yaml): a session's mouse under a real rig's camera.
    Moseq(MoseqArgs),
}

#[derive(Debug, Args)]
pub struct MoseqArgs {
    /// The recording directory to create.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Number of depth frames.
    #[arg(long, value_name = "N", default_value_t = 900, value_parser = parse_images, allow_negative_numbers = true)]
    frames: u64,
    /// Frame rate (timestamps in depth_ts.txt).
    #[arg(long, value_name = "FPS", default_value_t = 30.0, value_parser = parse_fps, allow_negative_numbers = true)]
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
    #[command(flatten)]
    noise: NoiseArgs,
    /// Depth camera noise model: none, structured-light or tof.
    #[arg(long = "noise-model", value_name = "MODEL", default_value = "tof")]
    noise_model: NoiseModel,
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
    crate::app::parse_ranged(s, "a camera height in millimetres", 300.0, 2000.0)
}

fn parse_tilt(s: &str) -> Result<f64, String> {
    crate::app::parse_ranged(s, "a tilt in degrees", 0.0, 30.0)
}

#[derive(Debug, Args)]
pub struct NoiseArgs {
    /// Gaussian depth noise, standard deviation in millimetres.
    #[arg(long = "noise-mm", value_name = "SIGMA", default_value_t = 0.0, value_parser = parse_noise_mm, allow_negative_numbers = true)]
    noise_mm: f64,
}

#[derive(Debug, Args)]
pub struct DatasetArgs {
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
    /// Print what was written as one JSON object (`out`, `depth_frames`, `color_frames`,
    /// `preview`).
    #[arg(long)]
    json: bool,
    /// standard: mice like the ones the bundled forests were trained on; varied: sizes,
    /// body shapes, backs and tails well outside that range (a stress test); mixed: varied
    /// for odd seeds.
    #[arg(long, value_name = "KIND", default_value = "standard")]
    mice: crate::synth::Mice,
    /// What the mouse does: anything (mixed), stays in place (still: standing, sniffing,
    /// grooming, rearing, bending), or walks (walking).
    #[arg(long, value_name = "mixed|still|walking", default_value = "mixed", value_parser = parse_activity)]
    activity: crate::synth::animate::Activity,
    /// visible: the tail rendered; hidden: not rendered, as a depth camera that does not see a
    /// 3-5 mm tail shows it (the truth keeps its joints).
    #[arg(long, value_name = "visible|hidden", default_value = "visible", value_parser = parse_tail, action = clap::ArgAction::Set)]
    tail: bool,
    /// Replace the output directory if it is not empty.
    #[arg(long)]
    force: bool,
}

/// `mousepose synth ...`.
pub fn run(command: SynthCommand) -> Outcome {
    match command {
        SynthCommand::Dataset(args) => synth_dataset(&args),
        SynthCommand::Session(args) => synth_session(&args),
        SynthCommand::Chessboard(args) => crate::app::calibrate::synth_chessboard(&args),
        SynthCommand::Moseq(args) => synth_moseq(&args),
    }
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
    };
    // A size the camera table lacks is the user's mistake: said before anything is written.
    moseq_camera(&spec).map_err(crate::app::Failure::usage)?;
    let staging = Staging::new(&args.out, args.force).map_err(output_failure)?;
    let bar = progress::bar(spec.frames, "rendering");
    write_moseq(staging.path(), &spec, |done, _| bar.set_position(done))
        .with_context(|| format!("writing the MoSeq recording {:?}", args.out))?;
    bar.finish_and_clear();
    let out = staging.commit()?;
    tracing::info!(message = "MoSeq recording written.", path = %out.display(), frames = spec.frames);
    Ok(())
}

fn synth_dataset(args: &DatasetArgs) -> Outcome {
    let staging = Staging::new(&args.out, args.force).map_err(output_failure)?;
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
    };
    let bar = progress::bar(spec.count, "rendering");
    let rig = crate::core::geometry::Rig::default_rig();
    write_dataset(staging.path(), &rig, &spec, |done| bar.set_position(done))
        .with_context(|| format!("writing dataset {:?}", args.out))?;
    bar.finish_and_clear();
    let out = staging.commit()?;
    tracing::info!(message = "Dataset written.", path = %out.display(), images = spec.count);
    if args.json {
        crate::app::print_json(&serde_json::json!({ "out": out, "images": spec.count }))?;
    }
    Ok(())
}

fn synth_session(args: &SessionArgs) -> Outcome {
    let staging = Staging::new(&args.out, args.force).map_err(output_failure)?;
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
        mice: args.mice,
        activity: args.activity,
        tail_hidden: args.tail,
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
    if args.json {
        crate::app::print_json(&serde_json::json!({
            "out": out,
            "depth_frames": summary.depth_frames,
            "color_frames": summary.color_frames,
            "preview": out.join(crate::synth::session::PREVIEW_FILE),
        }))?;
    }
    Ok(())
}

/// `--tail visible|hidden`: whether the tail is hidden.
fn parse_tail(s: &str) -> Result<bool, String> {
    match s {
        "visible" => Ok(false),
        "hidden" => Ok(true),
        _ => Err(format!("{s:?} is not a tail: visible or hidden")),
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
