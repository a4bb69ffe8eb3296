//! The calibration engines behind `mousepose calibrate intrinsics|extrinsics` and `mousepose
//! synth chessboard`: options in, a summary out (its JSON, and the table the command prints).

use crate::engine::progress::Progress;
use crate::engine::{Exists, Failure, output_failure};
use crate::io::output::Staging;
use crate::synth::chessboard::{ChessboardSpec, write_chessboards};
use crate::vision::calibrate::CalibrationError;
use crate::vision::calibrate::extrinsics::{self, ExtrinsicsView};
use crate::vision::calibrate::{Board, calibrate_intrinsics, load_intrinsics};
use anyhow::Context as _;
use serde::Serialize;
use std::fmt::Write as _;

use std::path::{Path, PathBuf};

/// What `calibrate intrinsics` works on (see its `--help`).
#[derive(Clone, Debug)]
pub struct IntrinsicsOptions {
    /// The chessboard views, a glob pattern (`None` with `openni`).
    pub images: Option<String>,
    /// Read the depth camera's field of view from this OpenNI device instead.
    pub openni: Option<String>,
    /// Inner corners of the board, COLSxROWS.
    pub board: String,
    /// The side of one square, millimetres.
    pub square_mm: f64,
    /// The intrinsics file to write.
    pub out: PathBuf,
    /// Replace the output file if it exists.
    pub force: bool,
}

/// What `calibrate extrinsics` works on (see its `--help`).
#[derive(Clone, Debug)]
pub struct ExtrinsicsOptions {
    pub depth_intrinsics: PathBuf,
    pub color_intrinsics: PathBuf,
    pub depth_image: PathBuf,
    pub color_image: PathBuf,
    /// Inner corners of the board, COLSxROWS.
    pub board: String,
    /// The side of one square, millimetres.
    pub square_mm: f64,
    pub depth_serial: Option<String>,
    pub color_serial: Option<String>,
    /// The rig calibration file to write.
    pub out: PathBuf,
    /// Write report.json, report.txt and the views with the board's axes into this directory.
    pub report: Option<PathBuf>,
    /// A known rig calibration to measure each camera's pose error against.
    pub truth: Option<PathBuf>,
    /// Replace the output file and report directory if they exist.
    pub force: bool,
}

/// What `synth chessboard` renders (see its `--help`).
#[derive(Clone, Debug)]
pub struct ChessboardOptions {
    /// The directory to create.
    pub out: PathBuf,
    /// Inner corners of the board, COLSxROWS.
    pub board: String,
    /// The side of one square, millimetres.
    pub square_mm: f64,
    /// Intrinsics views per camera.
    pub views: u32,
    /// Seed of the board poses, lighting and noise.
    pub seed: u64,
    /// The colour camera's binning (1, 2 or 4).
    pub color_binning: u32,
    /// Replace the output directory if it is not empty.
    pub force: bool,
}

fn refuse_existing(path: &Path, force: bool) -> Result<(), Failure> {
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

/// What `calibrate intrinsics` found and wrote: its `--json` (the command line prints it as
/// text otherwise).
#[derive(Clone, Debug, Serialize)]
pub struct IntrinsicsSummary {
    pub out: String,
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub distortion: [f64; 5],
    pub rms: Option<f64>,
    pub per_view_errors: Vec<f64>,
    pub views: Vec<String>,
    pub skipped: Vec<String>,
    pub source: &'static str,
    /// The depth stream's horizontal and vertical fields of view, degrees (`openni` only).
    #[serde(skip)]
    pub field_of_view_deg: Option<[f64; 2]>,
}

fn board(size: &str, square_mm: f64) -> Result<Board, Failure> {
    Board::parse(size, square_mm).map_err(Failure::usage)
}

/// `mousepose calibrate intrinsics`: one camera's intrinsics from chessboard views (or the
/// depth camera's from OpenNI), written to `options.out`.
///
/// # Errors
/// A file in the way, a bad board, views without a board (the user's), or a failure on the way.
pub fn intrinsics(options: &IntrinsicsOptions) -> Result<IntrinsicsSummary, Failure> {
    refuse_existing(&options.out, options.force)?;
    let board = board(&options.board, options.square_mm)?;
    if let Some(uri) = &options.openni {
        let found = crate::runtime::capture::openni::depth_intrinsics(uri)
            .with_context(|| format!("reading OpenNI device {uri:?}"))?;
        crate::vision::calibrate::field_of_view::save(&found, &options.out).map_err(calibration_failure)?;
        return Ok(IntrinsicsSummary {
            out: options.out.display().to_string(),
            width: found.intrinsics.width,
            height: found.intrinsics.height,
            fx: found.intrinsics.fx,
            fy: found.intrinsics.fy,
            cx: found.intrinsics.cx,
            cy: found.intrinsics.cy,
            distortion: found.intrinsics.distortion,
            rms: None,
            per_view_errors: Vec::new(),
            views: Vec::new(),
            skipped: Vec::new(),
            source: "openni",
            field_of_view_deg: Some([found.hfov_deg, found.vfov_deg]),
        });
    }
    let pattern = options.images.as_deref().unwrap_or_default();
    let images = expand_glob(pattern)?;
    let result = calibrate_intrinsics(&images, &board).map_err(calibration_failure)?;
    result.save(&options.out).map_err(calibration_failure)?;
    let i = &result.intrinsics;
    Ok(IntrinsicsSummary {
        out: options.out.display().to_string(),
        width: i.width,
        height: i.height,
        fx: i.fx,
        fy: i.fy,
        cx: i.cx,
        cy: i.cy,
        distortion: i.distortion,
        rms: Some(result.rms_px),
        per_view_errors: result.per_view_errors_px.clone(),
        views: result.views.clone(),
        skipped: result.skipped.clone(),
        source: "chessboard",
        field_of_view_deg: None,
    })
}

/// What `calibrate extrinsics` found and wrote: its `--json` (and `report.json`), and the
/// table of `report.txt`.
#[derive(Clone, Debug, Serialize)]
pub struct ExtrinsicsSummary {
    pub out: String,
    pub depth: extrinsics::CameraReport,
    pub color: extrinsics::CameraReport,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error_vs_truth: Option<std::collections::BTreeMap<&'static str, PoseError>>,
    /// The table of both cameras' poses (`report.txt`).
    #[serde(skip)]
    pub table: String,
}

/// A camera's pose error against a known calibration.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct PoseError {
    pub position_mm: f64,
    pub rotation_deg: f64,
}

/// `mousepose calibrate extrinsics`: both cameras' poses from one board on the glass, written
/// to `options.out` (and a report into `options.report`).
///
/// # Errors
/// A file in the way, a bad board or intrinsics file, a board not found (the user's), or a
/// failure on the way.
pub fn extrinsics(options: &ExtrinsicsOptions) -> Result<ExtrinsicsSummary, Failure> {
    refuse_existing(&options.out, options.force)?;
    let board = board(&options.board, options.square_mm)?;
    board.check_orientable().map_err(Failure::usage)?;
    let staging = options
        .report
        .as_deref()
        .map(|dir| Staging::new(dir, options.force))
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
    let depth = view(&options.depth_intrinsics, &options.depth_image, &options.depth_serial)?;
    let color = view(&options.color_intrinsics, &options.color_image, &options.color_serial)?;
    let result = extrinsics::calibrate_extrinsics(&depth, &color, &board).map_err(calibration_failure)?;
    result.calibration.save(&options.out).map_err(calibration_failure)?;
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
    let error_vs_truth = match &options.truth {
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
    let mut json = ExtrinsicsSummary {
        out: options.out.display().to_string(),
        depth: result.depth.clone(),
        color: result.color.clone(),
        error_vs_truth,
        table: String::new(),
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
    json.table = table;
    Ok(json)
}

/// What `synth chessboard` wrote.
#[derive(Clone, Debug, Serialize)]
pub struct ChessboardSummary {
    /// The directory written.
    pub out: PathBuf,
    /// Intrinsics views per camera.
    pub views: u32,
}

/// `mousepose synth chessboard`.
///
/// # Errors
/// A bad board, an output directory that may not be replaced, or a render that cannot be written.
pub fn synth_chessboard(options: &ChessboardOptions, progress: &dyn Progress) -> Result<ChessboardSummary, Failure> {
    let board = board(&options.board, options.square_mm)?;
    if ![1, 2, 4].contains(&options.color_binning) {
        return Err(Failure::usage(anyhow::anyhow!(
            "expected a binning factor of 1, 2 or 4, got {}",
            options.color_binning
        )));
    }
    let staging = Staging::new(&options.out, options.force).map_err(output_failure)?;
    let spec = ChessboardSpec {
        board,
        views: options.views,
        seed: options.seed,
        color_binning: options.color_binning,
    };
    let rig = crate::core::geometry::Rig::default_rig().with_color_binning(options.color_binning);
    progress.start("rendering", u64::from(options.views) * 2 + 2);
    write_chessboards(staging.path(), &rig, &spec, |done| progress.set_done(done))
        .with_context(|| format!("writing chessboard views to {:?}", options.out))?;
    progress.finish();
    let out = staging.commit()?;
    tracing::info!(message = "Chessboard views written.", path = %out.display(), views = options.views);
    Ok(ChessboardSummary {
        out,
        views: options.views,
    })
}
