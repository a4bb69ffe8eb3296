//! Two-camera calibration: each camera's intrinsics from chessboard views (or the depth
//! camera's from OpenNI), then both cameras posed against one board lying on the glass, which
//! fixes the world frame. The results are OpenCV FileStorage YAML files (`docs/FORMATS.md`).
//!
//! [`RigCalibration`] is what `record`, `run` and `replay` load: [`RigCalibration::load`],
//! [`RigCalibration::rig`] and [`RigCalibration::check_matches`] against a session.

pub mod board;
pub mod extrinsics;
pub mod field_of_view;
pub mod intrinsics;
mod storage;

pub use board::{Board, BoardError};
pub use extrinsics::{CameraPose, solve_pose};
pub use intrinsics::{IntrinsicsCalibration, calibrate_intrinsics};

use crate::core::geometry::{Camera, Intrinsics, Rig};
use crate::io::session::{CameraRole, SessionMeta};
use nalgebra::{Isometry3, Matrix3, Matrix4, Rotation3, Translation3, UnitQuaternion};
use std::path::{Path, PathBuf};
use storage::{Node, YamlReader, YamlWriter};

/// The `format` value of a rig calibration file.
pub const RIG_FORMAT_NAME: &str = "mousepose-rig-calibration";
/// The rig calibration format version this module writes and reads.
pub const RIG_FORMAT_VERSION: i32 = 1;
/// The `format` value of a camera intrinsics file.
pub const INTRINSICS_FORMAT_NAME: &str = "mousepose-camera-intrinsics";
/// The intrinsics format version this module writes (files without one are read as OpenCV's).
pub const INTRINSICS_FORMAT_VERSION: i32 = 1;

/// Errors of calibration: reading and writing calibration files, finding boards, solving.
#[derive(Debug, thiserror::Error)]
pub enum CalibrationError {
    #[error("cannot read or write {path:?}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("calibration file {0:?} is empty")]
    Empty(PathBuf),
    #[error("cannot {action} {path:?} as OpenCV FileStorage YAML")]
    OpenCv {
        path: PathBuf,
        action: &'static str,
        #[source]
        source: CvError,
    },
    #[error("calibration file {path:?} has no {node:?} node")]
    MissingNode { path: PathBuf, node: String },
    #[error("calibration file {path:?}: {node:?} is not {expected}")]
    WrongType {
        path: PathBuf,
        node: String,
        expected: String,
    },
    #[error("calibration file {path:?}: {node:?} is a {found} matrix, expected {expected}")]
    MatrixShape {
        path: PathBuf,
        node: String,
        expected: String,
        found: String,
    },
    #[error("calibration file {path:?} is not a rig calibration (format {found:?}, expected {expected:?})")]
    WrongFormat {
        path: PathBuf,
        found: String,
        expected: &'static str,
    },
    #[error("calibration file {path:?} has format_version {found}, this mousepose reads {supported}")]
    UnknownVersion { path: PathBuf, found: i32, supported: i32 },
    #[error("calibration file {path:?}: {what}")]
    Invalid { path: PathBuf, what: String },
    #[error(
        "calibration {calibration} is for a {calib_width}x{calib_height} {role} camera, but {target}'s {role} camera is {width}x{height}"
    )]
    SizeMismatch {
        calibration: String,
        target: String,
        role: CameraRole,
        calib_width: u32,
        calib_height: u32,
        width: u32,
        height: u32,
    },
    #[error(
        "calibration {calibration} is for the {role} camera with serial {calib_serial:?}, but {target}'s has serial {serial:?}"
    )]
    SerialMismatch {
        calibration: String,
        target: String,
        role: CameraRole,
        calib_serial: String,
        serial: String,
    },
    #[error(transparent)]
    Board(#[from] BoardError),
    #[error(transparent)]
    Intrinsics(#[from] intrinsics::IntrinsicsError),
    #[error(transparent)]
    Extrinsics(#[from] extrinsics::ExtrinsicsError),
    #[error("cannot encode the picture of the board's axes as PNG")]
    Png(#[source] png::EncodingError),
    #[error("OpenCV failed to {what}")]
    Solve {
        what: String,
        #[source]
        source: CvError,
    },
}

impl CalibrationError {
    /// True when the input is at fault (a file that is not a calibration, a board not found,
    /// too few views, sizes that do not match), false when the work itself failed (I/O, OpenCV,
    /// a device): the command line's exit codes 1 and 2.
    pub fn is_input_problem(&self) -> bool {
        match self {
            Self::Io { .. } | Self::Solve { .. } => false,
            Self::OpenCv { action, .. } => *action == "parse",
            Self::Board(BoardError::OpenCv { .. }) => false,
            _ => true,
        }
    }
}

/// An OpenCV error shown on one line (OpenCV's own messages hold newlines); the original is
/// kept whole in the field.
#[derive(Debug)]
pub struct CvError(pub opencv_calib::Error);

impl std::fmt::Display for CvError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let message = self.0.message.split_whitespace().collect::<Vec<_>>().join(" ");
        write!(f, "{message}")
    }
}

impl std::error::Error for CvError {}

impl From<opencv_calib::Error> for CvError {
    fn from(e: opencv_calib::Error) -> Self {
        Self(e)
    }
}

/// One camera of a rig calibration.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraCalibration {
    pub intrinsics: Intrinsics,
    /// The camera's pose: `p_world = world_from_camera * p_camera`.
    pub world_from_camera: Isometry3<f64>,
    /// RMS reprojection error of the board corners in the extrinsics view, pixels (0 for an
    /// exact synthetic calibration).
    pub reprojection_rms_px: f64,
    /// The camera's serial number, when known.
    pub serial: Option<String>,
}

impl CameraCalibration {
    /// The camera as the geometry module uses it.
    pub fn camera(&self) -> Camera {
        Camera {
            intrinsics: self.intrinsics,
            world_from_camera: self.world_from_camera,
        }
    }
}

/// A two-camera rig calibration: the file `calibrate extrinsics` writes and `record`, `run`
/// and `replay` read.
#[derive(Clone, Debug, PartialEq)]
pub struct RigCalibration {
    pub depth: CameraCalibration,
    pub color: CameraCalibration,
    /// The board used, when known.
    pub board: Option<Board>,
    /// The file it was loaded from (named in errors), if any.
    pub source: Option<PathBuf>,
}

impl RigCalibration {
    /// An exact calibration of a known rig (synthetic sessions and renders).
    pub fn from_rig(rig: &Rig) -> Self {
        let cam = |c: &Camera| CameraCalibration {
            intrinsics: c.intrinsics,
            world_from_camera: c.world_from_camera,
            reprojection_rms_px: 0.0,
            serial: None,
        };
        Self {
            depth: cam(&rig.depth),
            color: cam(&rig.color),
            board: None,
            source: None,
        }
    }

    /// The rig as the rest of mousepose uses it.
    pub fn rig(&self) -> Rig {
        Rig {
            depth: self.depth.camera(),
            color: self.color.camera(),
        }
    }

    /// The calibration of one camera.
    pub fn camera(&self, role: CameraRole) -> &CameraCalibration {
        match role {
            CameraRole::Depth => &self.depth,
            CameraRole::Color => &self.color,
        }
    }

    fn name(&self) -> String {
        match &self.source {
            Some(p) => format!("{p:?}"),
            None => "(not from a file)".to_owned(),
        }
    }

    /// Refuses a calibration made for another rig than the session's: an image size that
    /// differs from a session camera's, or a serial that differs when both sides know it.
    /// A session without a colour camera is checked on its depth camera only.
    ///
    /// # Errors
    /// [`CalibrationError::SizeMismatch`] or [`CalibrationError::SerialMismatch`], naming both.
    pub fn check_matches(&self, meta: &SessionMeta) -> Result<(), CalibrationError> {
        for role in [CameraRole::Depth, CameraRole::Color] {
            if let Some(cam) = meta.camera(role) {
                self.check_camera(role, cam.width, cam.height, Some(&cam.serial), "the session")?;
            }
        }
        Ok(())
    }

    /// Refuses a calibration whose `role` camera is not `width` x `height` or, when both are
    /// known and not empty, has another serial. `target` names what is checked ("the rig config").
    ///
    /// # Errors
    /// [`CalibrationError::SizeMismatch`] or [`CalibrationError::SerialMismatch`].
    pub fn check_camera(
        &self,
        role: CameraRole,
        width: u32,
        height: u32,
        serial: Option<&str>,
        target: &str,
    ) -> Result<(), CalibrationError> {
        let c = self.camera(role);
        if (c.intrinsics.width, c.intrinsics.height) != (width, height) {
            return Err(CalibrationError::SizeMismatch {
                calibration: self.name(),
                target: target.to_owned(),
                role,
                calib_width: c.intrinsics.width,
                calib_height: c.intrinsics.height,
                width,
                height,
            });
        }
        let ours = c.serial.as_deref().unwrap_or_default();
        let theirs = serial.unwrap_or_default();
        if !ours.is_empty() && !theirs.is_empty() && ours != theirs {
            return Err(CalibrationError::SerialMismatch {
                calibration: self.name(),
                target: target.to_owned(),
                role,
                calib_serial: ours.to_owned(),
                serial: theirs.to_owned(),
            });
        }
        Ok(())
    }

    /// Reads a rig calibration file.
    ///
    /// # Errors
    /// The file cannot be read or parsed, is another kind of file or version, or a node is
    /// missing, has the wrong type or shape, or holds an impossible value.
    pub fn load(path: &Path) -> Result<Self, CalibrationError> {
        let doc = YamlReader::open(path)?;
        let format = doc.require("format")?.text()?;
        if format != RIG_FORMAT_NAME {
            return Err(CalibrationError::WrongFormat {
                path: path.to_owned(),
                found: format,
                expected: RIG_FORMAT_NAME,
            });
        }
        let version = doc.require("format_version")?.int()?;
        if version != RIG_FORMAT_VERSION {
            return Err(CalibrationError::UnknownVersion {
                path: path.to_owned(),
                found: version,
                supported: RIG_FORMAT_VERSION,
            });
        }
        let board = match doc.get("board")? {
            Some(node) => {
                let size = node.text()?;
                let square = doc.require("square_mm")?.real()?;
                Some(Board::parse(&size, square).map_err(|e| CalibrationError::Invalid {
                    path: path.to_owned(),
                    what: e.to_string(),
                })?)
            }
            None => None,
        };
        let depth = read_camera(&doc.require("depth")?, path)?;
        let color = read_camera(&doc.require("color")?, path)?;
        Ok(Self {
            depth,
            color,
            board,
            source: Some(path.to_owned()),
        })
    }

    /// Writes the calibration to `path` atomically (replacing a file there).
    ///
    /// # Errors
    /// OpenCV cannot compose the YAML or the file cannot be written.
    pub fn save(&self, path: &Path) -> Result<(), CalibrationError> {
        let mut w = YamlWriter::new(path)?;
        w.text("format", RIG_FORMAT_NAME)?;
        w.int("format_version", RIG_FORMAT_VERSION)?;
        if let Some(board) = &self.board {
            w.text("board", &board.size_name())?;
            w.real("square_mm", board.square_mm)?;
        }
        for (name, cam) in [("depth", &self.depth), ("color", &self.color)] {
            w.begin_map(name)?;
            write_intrinsics(&mut w, &cam.intrinsics)?;
            let m = cam.world_from_camera.to_homogeneous();
            let data: Vec<f64> = (0..4).flat_map(|r| (0..4).map(move |c| m[(r, c)])).collect();
            w.matrix("world_from_camera", 4, 4, &data)?;
            w.real("reprojection_rms_px", cam.reprojection_rms_px)?;
            if let Some(serial) = cam.serial.as_deref().filter(|s| !s.is_empty()) {
                w.text("serial", serial)?;
            }
            w.end_map()?;
        }
        w.finish()
    }
}

/// Writes `image_width`, `image_height`, `camera_matrix` and `distortion_coefficients`.
fn write_intrinsics(w: &mut YamlWriter, i: &Intrinsics) -> Result<(), CalibrationError> {
    w.int("image_width", i.width as i32)?;
    w.int("image_height", i.height as i32)?;
    w.matrix(
        "camera_matrix",
        3,
        3,
        &[i.fx, 0.0, i.cx, 0.0, i.fy, i.cy, 0.0, 0.0, 1.0],
    )?;
    w.matrix("distortion_coefficients", 1, 5, &i.distortion)
}

/// Reads the four intrinsics nodes of a map (or of the document's top level).
fn read_intrinsics<'a>(
    get: impl Fn(&str) -> Result<Node<'a>, CalibrationError>,
    path: &Path,
) -> Result<Intrinsics, CalibrationError> {
    let invalid = |what: String| CalibrationError::Invalid {
        path: path.to_owned(),
        what,
    };
    let size = |name: &str| -> Result<u32, CalibrationError> {
        let v = get(name)?.int()?;
        u32::try_from(v)
            .ok()
            .filter(|&v| (1..=65_535).contains(&v))
            .ok_or_else(|| invalid(format!("{name} {v} is not an image size")))
    };
    let width = size("image_width")?;
    let height = size("image_height")?;
    let k = get("camera_matrix")?.matrix(3, 3)?;
    if k[0] <= 0.0 || k[4] <= 0.0 || k[1] != 0.0 || k[3] != 0.0 || k[6] != 0.0 || k[7] != 0.0 || k[8] != 1.0 {
        return Err(invalid(
            "camera_matrix is not [fx 0 cx; 0 fy cy; 0 0 1] with positive focal lengths".to_owned(),
        ));
    }
    let d = get("distortion_coefficients")?.reals()?;
    let mut distortion = [0.0; 5];
    match d.len() {
        4 | 5 => distortion[..d.len()].copy_from_slice(&d),
        n if n > 5 && d[5..].iter().all(|&v| v == 0.0) => distortion.copy_from_slice(&d[..5]),
        n => {
            return Err(invalid(format!(
                "distortion_coefficients has {n} values; mousepose uses OpenCV's five [k1, k2, p1, p2, k3]"
            )));
        }
    }
    Ok(Intrinsics {
        width,
        height,
        fx: k[0],
        fy: k[4],
        cx: k[2],
        cy: k[5],
        distortion,
    })
}

fn read_camera(node: &Node<'_>, path: &Path) -> Result<CameraCalibration, CalibrationError> {
    let intrinsics = read_intrinsics(|name| node.require(name), path)?;
    let m = node.require("world_from_camera")?.matrix(4, 4)?;
    let world_from_camera = isometry_from_rows(&m).ok_or_else(|| CalibrationError::Invalid {
        path: path.to_owned(),
        what: "world_from_camera is not a rigid transform (rotation and translation, last row 0 0 0 1)".to_owned(),
    })?;
    let reprojection_rms_px = match node.get("reprojection_rms_px")? {
        Some(n) => n.real()?,
        None => 0.0,
    };
    let serial = node.get("serial")?.map(|n| n.text()).transpose()?;
    Ok(CameraCalibration {
        intrinsics,
        world_from_camera,
        reprojection_rms_px,
        serial,
    })
}

/// A rigid transform from a row-major 4x4 matrix; `None` unless the upper-left 3x3 is a
/// rotation (within 1e-6) and the last row is `0 0 0 1`.
pub fn isometry_from_rows(m: &[f64]) -> Option<Isometry3<f64>> {
    if m.len() != 16 {
        return None;
    }
    let h = Matrix4::from_row_slice(m);
    if h.row(3)
        .iter()
        .zip([0.0, 0.0, 0.0, 1.0])
        .any(|(a, b)| (a - b).abs() > 1e-9)
    {
        return None;
    }
    let r: Matrix3<f64> = h.fixed_view::<3, 3>(0, 0).into_owned();
    if (r.transpose() * r - Matrix3::identity()).abs().max() > 1e-6 || r.determinant() < 0.0 {
        return None;
    }
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    Some(Isometry3::from_parts(
        Translation3::new(h[(0, 3)], h[(1, 3)], h[(2, 3)]),
        rotation,
    ))
}

/// Reads one camera's intrinsics file (what `calibrate intrinsics` writes, or OpenCV's own
/// calibration sample output: `image_width`, `image_height`, `camera_matrix`,
/// `distortion_coefficients` at the top level).
///
/// # Errors
/// As [`RigCalibration::load`].
pub fn load_intrinsics(path: &Path) -> Result<Intrinsics, CalibrationError> {
    let doc = YamlReader::open(path)?;
    if let Some(format) = doc.get("format")? {
        let format = format.text()?;
        if format == RIG_FORMAT_NAME {
            return Err(CalibrationError::Invalid {
                path: path.to_owned(),
                what: "this is a rig calibration, not one camera's intrinsics".to_owned(),
            });
        }
        if format != INTRINSICS_FORMAT_NAME {
            return Err(CalibrationError::WrongFormat {
                path: path.to_owned(),
                found: format,
                expected: INTRINSICS_FORMAT_NAME,
            });
        }
        let version = doc.require("format_version")?.int()?;
        if version != INTRINSICS_FORMAT_VERSION {
            return Err(CalibrationError::UnknownVersion {
                path: path.to_owned(),
                found: version,
                supported: INTRINSICS_FORMAT_VERSION,
            });
        }
    }
    read_intrinsics(|name| doc.require(name), path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rig_calibration_round_trips_through_yaml() {
        let dir = tempfile::tempdir().expect("tmp");
        let path = dir.path().join("rig.yaml");
        let mut cal = RigCalibration::from_rig(&Rig::default_rig().with_color_binning(2));
        cal.depth.serial = Some("1234".to_owned());
        cal.depth.intrinsics.distortion = [0.1, -0.02, 0.001, -0.002, 0.003];
        cal.board = Some(Board::parse("9x6", 20.0).expect("board"));
        cal.save(&path).expect("saves");
        let back = RigCalibration::load(&path).expect("loads");
        assert_eq!(back.source.as_deref(), Some(path.as_path()));
        assert_eq!(back.board, cal.board);
        assert_eq!(back.depth.serial.as_deref(), Some("1234"));
        for role in [CameraRole::Depth, CameraRole::Color] {
            let (a, b) = (cal.camera(role), back.camera(role));
            assert_eq!(a.intrinsics, b.intrinsics);
            let d = a.world_from_camera.inverse() * b.world_from_camera;
            assert!(d.translation.vector.norm() < 1e-9 && d.rotation.angle() < 1e-9);
        }
        let text = std::fs::read_to_string(&path).expect("read");
        assert!(text.starts_with("%YAML:1.0"), "{text}");
    }

    #[test]
    fn missing_node_and_bad_shape_are_named() {
        let dir = tempfile::tempdir().expect("tmp");
        let path = dir.path().join("rig.yaml");
        RigCalibration::from_rig(&Rig::default_rig())
            .save(&path)
            .expect("saves");
        let text = std::fs::read_to_string(&path).expect("read");
        let bad = text.replacen("world_from_camera", "world_from_kamera", 1);
        std::fs::write(&path, bad).expect("write");
        let e = RigCalibration::load(&path).expect_err("missing node").to_string();
        assert!(e.contains("depth.world_from_camera"), "{e}");
        let bad = text.replacen("format_version: 1", "format_version: 7", 1);
        std::fs::write(&path, bad).expect("write");
        let e = RigCalibration::load(&path).expect_err("version").to_string();
        assert!(e.contains("format_version 7"), "{e}");
    }
}
