//! One camera's intrinsics from chessboard views: corners found and refined in each view,
//! then OpenCV's camera calibration (five distortion coefficients, k3 held at zero, which
//! suits the lenses of this rig and keeps few views stable).

use super::board::{Board, read_grey};
use super::storage::YamlWriter;
use super::{CalibrationError, INTRINSICS_FORMAT_NAME, INTRINSICS_FORMAT_VERSION};
use crate::core::geometry::Intrinsics;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// The fewest views with a board found that `calibrate intrinsics` accepts.
pub const MIN_VIEWS: usize = 5;

/// Errors specific to intrinsics calibration.
#[derive(Debug, thiserror::Error)]
pub enum IntrinsicsError {
    #[error("no images given")]
    NoImages,
    #[error(
        "image {other:?} is {other_w}x{other_h}, but {first:?} is {first_w}x{first_h}; one camera's views must share a size"
    )]
    MixedSizes {
        first: PathBuf,
        first_w: u32,
        first_h: u32,
        other: PathBuf,
        other_w: u32,
        other_h: u32,
    },
    #[error("a {board} board was found in only {found} of {total} images, at least {needed} needed (not found in: {})", .skipped.join(", "))]
    TooFewViews {
        board: Board,
        found: usize,
        total: usize,
        needed: usize,
        skipped: Vec<String>,
    },
}

/// The result of calibrating one camera from chessboard views.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct IntrinsicsCalibration {
    pub intrinsics: Intrinsics,
    /// RMS reprojection error over all corners of all views, pixels.
    pub rms_px: f64,
    /// RMS reprojection error of each used view, pixels, in the order of `views`.
    pub per_view_errors_px: Vec<f64>,
    /// The views used (file names as given).
    pub views: Vec<String>,
    /// The views without a board, skipped.
    pub skipped: Vec<String>,
    #[serde(skip)]
    pub board: Board,
}

impl IntrinsicsCalibration {
    /// Writes the OpenCV FileStorage YAML file (`docs/FORMATS.md`) atomically.
    ///
    /// # Errors
    /// OpenCV cannot compose the YAML or the file cannot be written.
    pub fn save(&self, path: &Path) -> Result<(), CalibrationError> {
        let mut w = YamlWriter::new(path)?;
        w.text("format", INTRINSICS_FORMAT_NAME)?;
        w.int("format_version", INTRINSICS_FORMAT_VERSION)?;
        super::write_intrinsics(&mut w, &self.intrinsics)?;
        w.real("rms", self.rms_px)?;
        if !self.per_view_errors_px.is_empty() {
            let n = self.per_view_errors_px.len();
            w.matrix("per_view_errors", n, 1, &self.per_view_errors_px)?;
        }
        if !self.views.is_empty() {
            w.texts("views", &self.views)?;
        }
        w.text("board", &self.board.size_name())?;
        w.real("square_mm", self.board.square_mm)?;
        w.finish()
    }
}

fn solve_err(what: &str) -> impl FnOnce(opencv_calib::Error) -> CalibrationError + '_ {
    move |source| CalibrationError::Solve {
        what: what.to_owned(),
        source: source.into(),
    }
}

/// Calibrates one camera from chessboard views. Views without a board are skipped and
/// listed; fewer than [`MIN_VIEWS`] usable views is an error.
///
/// # Errors
/// No images, an unreadable image, images of different sizes, too few views with a board, or
/// OpenCV failing.
pub fn calibrate_intrinsics(images: &[PathBuf], board: &Board) -> Result<IntrinsicsCalibration, CalibrationError> {
    if images.is_empty() {
        return Err(IntrinsicsError::NoImages.into());
    }
    let FoundViews {
        size,
        image_points,
        views,
        skipped,
    } = find_views(images, board)?;
    if views.len() < MIN_VIEWS {
        return Err(IntrinsicsError::TooFewViews {
            board: *board,
            found: views.len(),
            total: images.len(),
            needed: MIN_VIEWS,
            skipped,
        }
        .into());
    }
    let Some((_, size)) = size else {
        return Err(IntrinsicsError::NoImages.into());
    };
    let grid = board_grid(board);
    let object_points: Vec<Vec<[f32; 3]>> = (0..views.len()).map(|_| grid.clone()).collect();
    let criteria = opencv_calib::TermCriteria {
        kind: opencv_calib::TERM_COUNT | opencv_calib::TERM_EPS,
        max_count: 100,
        epsilon: f64::EPSILON,
    };
    let found = opencv_calib::calibrate_camera(
        &object_points,
        &image_points,
        size,
        opencv_calib::CALIB_FIX_K3,
        criteria,
    )
    .map_err(solve_err("calibrate the camera"))?;
    let mut distortion = [0.0; 5];
    for (v, d) in distortion.iter_mut().zip(&found.distortion) {
        *v = *d;
    }
    let k = found.camera_matrix;
    Ok(IntrinsicsCalibration {
        intrinsics: Intrinsics {
            width: size.0,
            height: size.1,
            fx: k[0],
            fy: k[4],
            cx: k[2],
            cy: k[5],
            distortion,
        },
        rms_px: found.rms,
        per_view_errors_px: found.per_view_errors,
        views,
        skipped,
        board: *board,
    })
}

/// The images' views of the board: their common size (and the first image, for messages),
/// each found board's corners and its image's name, and the images without a board.
struct FoundViews {
    size: Option<(PathBuf, (u32, u32))>,
    image_points: Vec<Vec<[f32; 2]>>,
    views: Vec<String>,
    skipped: Vec<String>,
}

/// Finds the board in each of `images`, refusing images of different sizes.
fn find_views(images: &[PathBuf], board: &Board) -> Result<FoundViews, CalibrationError> {
    let mut size: Option<(PathBuf, (u32, u32))> = None;
    let mut image_points: Vec<Vec<[f32; 2]>> = Vec::new();
    let mut views = Vec::new();
    let mut skipped = Vec::new();
    for path in images {
        let grey = read_grey(path)?;
        let s = (grey.width(), grey.height());
        match &size {
            None => size = Some((path.clone(), s)),
            Some((first, fs)) if *fs != s => {
                return Err(IntrinsicsError::MixedSizes {
                    first: first.clone(),
                    first_w: fs.0,
                    first_h: fs.1,
                    other: path.clone(),
                    other_w: s.0,
                    other_h: s.1,
                }
                .into());
            }
            Some(_) => {}
        }
        match board.find_corners(&grey, path)? {
            Some(corners) => {
                image_points.push(corners.iter().map(|p| [p.x as f32, p.y as f32]).collect());
                views.push(path.display().to_string());
            }
            None => skipped.push(path.display().to_string()),
        }
    }
    Ok(FoundViews {
        size,
        image_points,
        views,
        skipped,
    })
}

/// Any consistent planar object works for intrinsics: the detection order's own grid.
fn board_grid(board: &Board) -> Vec<[f32; 3]> {
    (0..board.rows)
        .flat_map(|j| (0..board.cols).map(move |i| (i, j)))
        .map(|(i, j)| {
            [
                (f64::from(i) * board.square_mm) as f32,
                (f64::from(j) * board.square_mm) as f32,
                0.0,
            ]
        })
        .collect()
}
