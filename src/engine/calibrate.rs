//! `mousepose calibrate intrinsics|extrinsics` and `mousepose synth chessboard`: arguments
//! and the commands themselves, kept here so the top-level CLI only delegates.

use crate::app::{Outcome, print};
use crate::engine::{Exists, Failure, output_failure};
use crate::io::output::Staging;
use crate::synth::chessboard::{ChessboardSpec, write_chessboards};
use crate::vision::calibrate::CalibrationError;
use crate::vision::calibrate::extrinsics::{self, ExtrinsicsView};
use crate::vision::calibrate::{Board, calibrate_intrinsics, load_intrinsics};
use anyhow::Context as _;
use clap::{Args, Subcommand};
use serde::Serialize;
use std::fmt::Write as _;

use std::path::{Path, PathBuf};

/// Calibrate the cameras: intrinsics of each, then both posed against a board on the glass.
#[derive(Debug, Subcommand)]
pub enum CalibrateCommand {
    /// One camera's intrinsics from chessboard views (or the depth camera's from OpenNI).
    Intrinsics(IntrinsicsArgs),
    /// Both cameras' poses from one board lying on the glass: the rig calibration.
    Extrinsics(ExtrinsicsArgs),
}

#[derive(Debug, Args)]
pub struct IntrinsicsArgs {
    /// The chessboard views, a glob pattern (quote it): "views/*.png".
    #[arg(
        long,
        value_name = "GLOB",
        required_unless_present = "openni",
        conflicts_with = "openni"
    )]
    pub images: Option<String>,
    /// Read the depth camera's field of view from OpenNI instead (a URI; `Dummy` for the test device).
    #[arg(long, value_name = "URI")]
    pub openni: Option<String>,
    /// Inner corners of the board, COLSxROWS.
    #[arg(long, default_value = "9x6")]
    pub board: String,
    /// The side of one square, millimetres.
    #[arg(long = "square-mm", value_name = "S", value_parser = parse_square_mm, allow_negative_numbers = true, default_value_t = 20.0)]
    pub square_mm: f64,
    /// The intrinsics file to write (OpenCV FileStorage YAML).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Replace the output file if it exists.
    #[arg(long)]
    pub force: bool,
}

#[derive(Debug, Args)]
pub struct ExtrinsicsArgs {
    /// The depth camera's intrinsics file.
    #[arg(long, value_name = "FILE")]
    pub depth_intrinsics: PathBuf,
    /// The colour camera's intrinsics file.
    #[arg(long, value_name = "FILE")]
    pub color_intrinsics: PathBuf,
    /// The depth camera's IR image of the board lying on the glass.
    #[arg(long, value_name = "IMG")]
    pub depth_image: PathBuf,
    /// The colour camera's image of the same board, seen from below.
    #[arg(long, value_name = "IMG")]
    pub color_image: PathBuf,
    /// Inner corners of the board, COLSxROWS (one side odd, the other even).
    #[arg(long, default_value = "9x6")]
    pub board: String,
    /// The side of one square, millimetres, as printed (it sets the scale of the poses).
    #[arg(long = "square-mm", value_name = "S", value_parser = parse_square_mm, allow_negative_numbers = true)]
    pub square_mm: f64,
    /// The depth camera's serial, stored in the calibration.
    #[arg(long, value_name = "SERIAL")]
    pub depth_serial: Option<String>,
    /// The colour camera's serial, stored in the calibration.
    #[arg(long, value_name = "SERIAL")]
    pub color_serial: Option<String>,
    /// The rig calibration file to write.
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Write report.json, report.txt and the views with the board's axes into this directory.
    #[arg(long, value_name = "DIR")]
    pub report: Option<PathBuf>,
    /// A known rig calibration (e.g. `truth.yaml` of `synth chessboard`): report each camera's
    /// position and rotation error against it.
    #[arg(long, value_name = "FILE")]
    pub truth: Option<PathBuf>,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Replace the output file and report directory if they exist.
    #[arg(long)]
    pub force: bool,
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
    #[arg(long = "square-mm", value_name = "S", value_parser = parse_square_mm, allow_negative_numbers = true, default_value_t = 40.0)]
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

fn refuse_existing(path: &Path, force: bool) -> Outcome {
    if path.exists() && !force {
        return Err(Failure::usage(Exists(path.to_owned())));
    }
    Ok(())
}

/// Expands a glob pattern into its matching files, sorted.
///
/// # Errors
/// A malformed pattern, or a pattern that matches no file.
pub fn expand_glob(pattern: &str) -> Result<Vec<PathBuf>, Failure> {
    let paths = glob::glob(pattern).map_err(|e| {
        Failure::usage(anyhow::Error::new(e).context(format!("image pattern {pattern:?} is not a valid glob")))
    })?;
    let mut files: Vec<PathBuf> = paths.filter_map(Result::ok).filter(|p| p.is_file()).collect();
    files.sort();
    if files.is_empty() {
        return Err(Failure::usage(anyhow::anyhow!(
            "image pattern {pattern:?} matches no files"
        )));
    }
    Ok(files)
}

/// A calibration error: the user's when the input cannot work (a board not found, views that
/// do not fit), the work's otherwise.
fn calibration_failure(e: CalibrationError) -> Failure {
    Failure::classed(e.is_input_problem(), e)
}

/// `mousepose calibrate ...`.
///
/// # Errors
/// Whatever the command meets; the message names the file at fault.
pub fn run(command: &CalibrateCommand) -> Outcome {
    match command {
        CalibrateCommand::Intrinsics(args) => intrinsics(args),
        CalibrateCommand::Extrinsics(args) => extrinsics_command(args),
    }
}

#[derive(Serialize)]
struct IntrinsicsJson<'a> {
    out: String,
    width: u32,
    height: u32,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    distortion: [f64; 5],
    rms: Option<f64>,
    per_view_errors: &'a [f64],
    views: &'a [String],
    skipped: &'a [String],
    source: &'static str,
}

fn parse_square_mm(s: &str) -> Result<f64, String> {
    crate::app::parse_ranged(s, "a square side in millimetres", 0.5, 1000.0)
}

fn board(size: &str, square_mm: f64) -> Result<Board, Failure> {
    Board::parse(size, square_mm).map_err(Failure::usage)
}

fn intrinsics(args: &IntrinsicsArgs) -> Outcome {
    refuse_existing(&args.out, args.force)?;
    let board = board(&args.board, args.square_mm)?;
    if let Some(uri) = &args.openni {
        let found = crate::vision::calibrate::openni::depth_intrinsics(uri)
            .with_context(|| format!("reading OpenNI device {uri:?}"))?;
        crate::vision::calibrate::openni::save(&found, &args.out).map_err(calibration_failure)?;
        let json = IntrinsicsJson {
            out: args.out.display().to_string(),
            width: found.intrinsics.width,
            height: found.intrinsics.height,
            fx: found.intrinsics.fx,
            fy: found.intrinsics.fy,
            cx: found.intrinsics.cx,
            cy: found.intrinsics.cy,
            distortion: found.intrinsics.distortion,
            rms: None,
            per_view_errors: &[],
            views: &[],
            skipped: &[],
            source: "openni",
        };
        if args.json {
            return Ok(print(&format!("{}\n", serde_json::to_string_pretty(&json)?))?);
        }
        return Ok(print(&format!(
            "{}x{} depth mode, field of view {:.2} x {:.2} degrees: fx {:.2} fy {:.2} cx {:.2} cy {:.2}; written to {:?}\n",
            found.intrinsics.width,
            found.intrinsics.height,
            found.hfov_deg,
            found.vfov_deg,
            found.intrinsics.fx,
            found.intrinsics.fy,
            found.intrinsics.cx,
            found.intrinsics.cy,
            args.out
        ))?);
    }
    let pattern = args.images.as_deref().unwrap_or_default();
    let images = expand_glob(pattern)?;
    let result = calibrate_intrinsics(&images, &board).map_err(calibration_failure)?;
    result.save(&args.out).map_err(calibration_failure)?;
    let i = &result.intrinsics;
    if args.json {
        let json = IntrinsicsJson {
            out: args.out.display().to_string(),
            width: i.width,
            height: i.height,
            fx: i.fx,
            fy: i.fy,
            cx: i.cx,
            cy: i.cy,
            distortion: i.distortion,
            rms: Some(result.rms_px),
            per_view_errors: &result.per_view_errors_px,
            views: &result.views,
            skipped: &result.skipped,
            source: "chessboard",
        };
        return Ok(print(&format!("{}\n", serde_json::to_string_pretty(&json)?))?);
    }
    let mut t = String::new();
    let _ = writeln!(t, "{:<40} {:>10}", "view", "rms px");
    for (v, e) in result.views.iter().zip(&result.per_view_errors_px) {
        let _ = writeln!(t, "{v:<40} {e:>10.3}");
    }
    for v in &result.skipped {
        let _ = writeln!(t, "{v:<40} {:>10}", "no board");
    }
    let _ = writeln!(
        t,
        "{}x{}: fx {:.2} fy {:.2} cx {:.2} cy {:.2}, distortion {:?}",
        i.width, i.height, i.fx, i.fy, i.cx, i.cy, i.distortion
    );
    let _ = writeln!(
        t,
        "rms {:.3} px over {} views ({} without a board skipped); written to {:?}",
        result.rms_px,
        result.views.len(),
        result.skipped.len(),
        args.out
    );
    Ok(print(&t)?)
}

#[derive(Serialize)]
struct ExtrinsicsJson<'a> {
    out: String,
    depth: &'a extrinsics::CameraReport,
    color: &'a extrinsics::CameraReport,
    #[serde(skip_serializing_if = "Option::is_none")]
    error_vs_truth: Option<std::collections::BTreeMap<&'static str, PoseError>>,
}

/// A camera's pose error against a known calibration.
#[derive(Clone, Copy, Debug, Serialize)]
struct PoseError {
    position_mm: f64,
    rotation_deg: f64,
}

fn extrinsics_command(args: &ExtrinsicsArgs) -> Outcome {
    refuse_existing(&args.out, args.force)?;
    let board = board(&args.board, args.square_mm)?;
    board.check_orientable().map_err(Failure::usage)?;
    let staging = args
        .report
        .as_deref()
        .map(|dir| Staging::new(dir, args.force))
        .transpose()
        .map_err(output_failure)?;
    let view = |file: &Path, image: &Path, serial: &Option<String>| -> Result<ExtrinsicsView, Failure> {
        Ok(ExtrinsicsView {
            intrinsics: load_intrinsics(file).map_err(calibration_failure)?,
            intrinsics_file: file.to_owned(),
            image: image.to_owned(),
            serial: serial.clone(),
        })
    };
    let depth = view(&args.depth_intrinsics, &args.depth_image, &args.depth_serial)?;
    let color = view(&args.color_intrinsics, &args.color_image, &args.color_serial)?;
    let result = extrinsics::calibrate_extrinsics(&depth, &color, &board).map_err(calibration_failure)?;
    result.calibration.save(&args.out).map_err(calibration_failure)?;
    let mut table = String::new();
    let _ = writeln!(
        table,
        "{:<6} {:>28} {:>12} {:>9} {:>9}",
        "camera", "centre mm (x, y, z)", "tilt deg", "rms px", "max px"
    );
    for (name, r) in [("depth", &result.depth), ("color", &result.color)] {
        let t = r.translation_mm;
        let _ = writeln!(
            table,
            "{name:<6} {:>28} {:>12.2} {:>9.3} {:>9.3}",
            format!("{:.1}, {:.1}, {:.1}", t[0], t[1], t[2]),
            r.tilt_deg,
            r.reprojection_rms_px,
            r.reprojection_max_px
        );
    }
    let error_vs_truth = match &args.truth {
        Some(path) => {
            let truth = crate::vision::calibrate::RigCalibration::load(path).map_err(calibration_failure)?;
            let mut errors = std::collections::BTreeMap::new();
            for (name, role) in [
                ("depth", crate::io::session::CameraRole::Depth),
                ("color", crate::io::session::CameraRole::Color),
            ] {
                let (position_mm, rotation_deg) = extrinsics::pose_difference(
                    &result.calibration.camera(role).world_from_camera,
                    &truth.camera(role).world_from_camera,
                );
                let _ = writeln!(
                    table,
                    "{name:<6} vs {}: {position_mm:.3} mm, {rotation_deg:.4} deg",
                    path.display()
                );
                errors.insert(
                    name,
                    PoseError {
                        position_mm,
                        rotation_deg,
                    },
                );
            }
            Some(errors)
        }
        None => None,
    };
    let json = ExtrinsicsJson {
        out: args.out.display().to_string(),
        depth: &result.depth,
        color: &result.color,
        error_vs_truth,
    };
    if let Some(staging) = staging {
        let dir = staging.path();
        let write = |name: &str, bytes: &[u8]| -> anyhow::Result<()> {
            let path = dir.join(name);
            std::fs::write(&path, bytes).with_context(|| format!("writing {path:?}"))
        };
        write(
            "report.json",
            format!("{}\n", serde_json::to_string_pretty(&json)?).as_bytes(),
        )?;
        write("report.txt", table.as_bytes())?;
        write("depth-axes.png", &result.depth_axes_png)?;
        write("color-axes.png", &result.color_axes_png)?;
        staging.commit()?;
    }
    if args.json {
        return Ok(print(&format!("{}\n", serde_json::to_string_pretty(&json)?))?);
    }
    let _ = writeln!(table, "rig calibration written to {:?}", args.out);
    Ok(print(&table)?)
}

/// `mousepose synth chessboard`.
///
/// # Errors
/// A bad board, an output directory that may not be replaced, or a render that cannot be written.
pub fn synth_chessboard(args: &ChessboardArgs) -> Outcome {
    let board = board(&args.board, args.square_mm)?;
    if ![1, 2, 4].contains(&args.color_binning) {
        return Err(Failure::usage(anyhow::anyhow!(
            "expected a binning factor of 1, 2 or 4, got {}",
            args.color_binning
        )));
    }
    let staging = Staging::new(&args.out, args.force).map_err(output_failure)?;
    let spec = ChessboardSpec {
        board,
        views: args.views,
        seed: args.seed,
        color_binning: args.color_binning,
    };
    let rig = crate::core::geometry::Rig::default_rig().with_color_binning(args.color_binning);
    let bar = crate::engine::progress::bar(u64::from(args.views) * 2 + 2, "rendering");
    write_chessboards(staging.path(), &rig, &spec, |done| bar.set_position(done))
        .with_context(|| format!("writing chessboard views to {:?}", args.out))?;
    bar.finish_and_clear();
    let out = staging.commit()?;
    tracing::info!(message = "Chessboard views written.", path = %out.display(), views = args.views);
    if args.json {
        crate::app::print_json(&serde_json::json!({ "out": out, "views": args.views }))?;
    }
    Ok(())
}
