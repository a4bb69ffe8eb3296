//! `mousepose calibrate intrinsics|extrinsics`: the arguments, handed to
//! [`crate::engine::calibrate`], and what it found printed.

use crate::app::Outcome;
use crate::app::output::{print, print_json};
use crate::app::parse;
use crate::engine::calibrate::{self, ExtrinsicsOptions, IntrinsicsOptions, IntrinsicsSummary};
use clap::{Args, Subcommand};
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
    #[arg(long = "square-mm", value_name = "S", value_parser = parse::square_mm, allow_negative_numbers = true, default_value_t = 20.0)]
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
    #[arg(long = "square-mm", value_name = "S", value_parser = parse::square_mm, allow_negative_numbers = true)]
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

/// `mousepose calibrate ...`.
///
/// # Errors
/// Whatever the command meets; the message names the file at fault.
pub fn command(command: &CalibrateCommand) -> Outcome {
    match command {
        CalibrateCommand::Intrinsics(args) => intrinsics(args),
        CalibrateCommand::Extrinsics(args) => extrinsics(args),
    }
}

fn intrinsics(args: &IntrinsicsArgs) -> Outcome {
    let summary = calibrate::intrinsics(&IntrinsicsOptions {
        images: args.images.clone(),
        openni: args.openni.clone(),
        board: args.board.clone(),
        square_mm: args.square_mm,
        out: args.out.clone(),
        force: args.force,
    })?;
    if args.json {
        return Ok(print_json(&summary)?);
    }
    Ok(print(&intrinsics_text(&summary, &args.out))?)
}

/// What `calibrate intrinsics` prints without `--json`: the depth mode and its fields of
/// view (OpenNI), or each view's error and the intrinsics found (chessboard views).
fn intrinsics_text(s: &IntrinsicsSummary, out: &Path) -> String {
    if let Some([hfov, vfov]) = s.field_of_view_deg {
        return format!(
            "{}x{} depth mode, field of view {:.2} x {:.2} degrees: fx {:.2} fy {:.2} cx {:.2} cy {:.2}; written to {:?}\n",
            s.width, s.height, hfov, vfov, s.fx, s.fy, s.cx, s.cy, out
        );
    }
    let mut t = String::new();
    let _ = writeln!(t, "{:<40} {:>10}", "view", "rms px");
    for (v, e) in s.views.iter().zip(&s.per_view_errors) {
        let _ = writeln!(t, "{v:<40} {e:>10.3}");
    }
    for v in &s.skipped {
        let _ = writeln!(t, "{v:<40} {:>10}", "no board");
    }
    let _ = writeln!(
        t,
        "{}x{}: fx {:.2} fy {:.2} cx {:.2} cy {:.2}, distortion {:?}",
        s.width, s.height, s.fx, s.fy, s.cx, s.cy, s.distortion
    );
    let _ = writeln!(
        t,
        "rms {:.3} px over {} views ({} without a board skipped); written to {:?}",
        s.rms.unwrap_or(f64::NAN),
        s.views.len(),
        s.skipped.len(),
        out
    );
    t
}

fn extrinsics(args: &ExtrinsicsArgs) -> Outcome {
    let summary = calibrate::extrinsics(&ExtrinsicsOptions {
        depth_intrinsics: args.depth_intrinsics.clone(),
        color_intrinsics: args.color_intrinsics.clone(),
        depth_image: args.depth_image.clone(),
        color_image: args.color_image.clone(),
        board: args.board.clone(),
        square_mm: args.square_mm,
        depth_serial: args.depth_serial.clone(),
        color_serial: args.color_serial.clone(),
        out: args.out.clone(),
        report: args.report.clone(),
        truth: args.truth.clone(),
        force: args.force,
    })?;
    if args.json {
        return Ok(print_json(&summary)?);
    }
    Ok(print(&format!(
        "{}rig calibration written to {:?}\n",
        summary.table, args.out
    ))?)
}
