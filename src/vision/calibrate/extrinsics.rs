//! Both cameras posed against one board lying on the glass: the board's frame becomes the
//! world frame (origin at the board's centre on the glass's top surface, x and y along the
//! board, z up towards the depth camera).
//!
//! The depth camera sees the board's printed side from above; the colour camera sees it from
//! below through the glass and the transparent film, mirrored. [`Board::physical_order`] maps
//! each view's detected corners onto the same physical corners, so both poses share one frame.

use super::board::{Board, GreyPicture, Side, read_grey};
use super::{CalibrationError, CameraCalibration, RigCalibration};
use crate::core::geometry::Intrinsics;
use crate::core::image::RgbImage;
use crate::io::session::CameraRole;
use nalgebra::{Isometry3, Point2, Point3, Translation3, UnitQuaternion, Vector3};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Errors specific to extrinsics calibration.
#[derive(Debug, thiserror::Error)]
pub enum ExtrinsicsError {
    #[error("{role} image {image:?} is {image_w}x{image_h}, but its intrinsics {intrinsics:?} are for {w}x{h}")]
    SizeMismatch {
        role: CameraRole,
        image: PathBuf,
        image_w: u32,
        image_h: u32,
        intrinsics: PathBuf,
        w: u32,
        h: u32,
    },
    #[error("the {role} camera's pose puts the board behind it ({image:?})")]
    Behind { role: CameraRole, image: PathBuf },
    #[error("the {role} camera is {side} the board in {image:?}, but it must be {expected} the glass")]
    WrongSide {
        role: CameraRole,
        image: PathBuf,
        side: &'static str,
        expected: &'static str,
    },
}

/// A camera's pose from PnP.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraPose {
    /// `p_world = world_from_camera * p_camera`.
    pub world_from_camera: Isometry3<f64>,
    /// RMS reprojection error of the corners, pixels.
    pub rms_px: f64,
    /// Largest reprojection error of one corner, pixels.
    pub max_px: f64,
}

fn cv_err(what: &str) -> impl FnOnce(opencv_calib::Error) -> CalibrationError + '_ {
    move |source| CalibrationError::Solve {
        what: what.to_owned(),
        source: source.into(),
    }
}

/// The camera matrix `[fx 0 cx; 0 fy cy; 0 0 1]`, row-major.
fn camera_matrix(i: &Intrinsics) -> [f64; 9] {
    [i.fx, 0.0, i.cx, 0.0, i.fy, i.cy, 0.0, 0.0, 1.0]
}

fn vec3(v: [f64; 3]) -> Vector3<f64> {
    Vector3::new(v[0], v[1], v[2])
}

fn array3(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// Poses a camera from corresponding world points and image points: OpenCV's iterative PnP,
/// then Levenberg-Marquardt refinement.
///
/// # Errors
/// Fewer than 4 points, mismatched lengths, or OpenCV failing.
pub fn solve_pose(
    object: &[Point3<f64>],
    image: &[Point2<f64>],
    intrinsics: &Intrinsics,
) -> Result<CameraPose, CalibrationError> {
    if object.len() != image.len() || object.len() < 4 {
        return Err(CalibrationError::Solve {
            what: format!(
                "pose a camera from {} world and {} image points",
                object.len(),
                image.len()
            ),
            source: opencv_calib::Error {
                operation: "solvePnP",
                message: "need at least 4 matching points".to_owned(),
            }
            .into(),
        });
    }
    let obj: Vec<[f32; 3]> = object.iter().map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect();
    let img: Vec<[f32; 2]> = image.iter().map(|p| [p.x as f32, p.y as f32]).collect();
    let k = camera_matrix(intrinsics);
    let d = &intrinsics.distortion;
    let pose = opencv_calib::solve_pnp(&obj, &img, &k, d, None, opencv_calib::SOLVEPNP_ITERATIVE)
        .map_err(cv_err("solve PnP"))?
        .ok_or_else(|| {
            cv_err("solve PnP")(opencv_calib::Error {
                operation: "solvePnP",
                message: "no pose found".to_owned(),
            })
        })?;
    let criteria = opencv_calib::TermCriteria {
        kind: opencv_calib::TERM_EPS | opencv_calib::TERM_COUNT,
        max_count: 100,
        epsilon: 1e-12,
    };
    let pose = opencv_calib::solve_pnp_refine_lm(&obj, &img, &k, d, pose, criteria).map_err(cv_err("refine PnP"))?;
    let r = vec3(pose.rvec);
    let t = vec3(pose.tvec);
    let camera_from_world = Isometry3::from_parts(Translation3::from(t), UnitQuaternion::from_scaled_axis(r));
    let mut sq = 0.0;
    let mut max_px: f64 = 0.0;
    for (p, q) in object.iter().zip(image) {
        let e = intrinsics
            .project(&(camera_from_world * p))
            .map_or(f64::INFINITY, |proj| (proj - q).norm());
        sq += e * e;
        max_px = max_px.max(e);
    }
    Ok(CameraPose {
        world_from_camera: camera_from_world.inverse(),
        rms_px: (sq / object.len() as f64).sqrt(),
        max_px,
    })
}

/// One camera's input to extrinsics calibration.
#[derive(Clone, Debug)]
pub struct ExtrinsicsView {
    pub intrinsics: Intrinsics,
    /// The file the intrinsics came from (named in errors).
    pub intrinsics_file: PathBuf,
    pub image: PathBuf,
    pub serial: Option<String>,
}

/// One camera's result, for reports and `--json`.
#[derive(Clone, Debug, Serialize)]
pub struct CameraReport {
    pub image: String,
    /// The camera's centre in the world frame, mm.
    pub translation_mm: [f64; 3],
    /// The rotation of `world_from_camera`, scalar first.
    pub rotation_quaternion_wxyz: [f64; 4],
    /// The rotation of `world_from_camera` as a rotation vector (axis times angle), radians.
    pub rotation_vector: [f64; 3],
    pub reprojection_rms_px: f64,
    pub reprojection_max_px: f64,
    /// The camera's optical axis's angle from straight down (depth) or straight up (colour), degrees.
    pub tilt_deg: f64,
}

/// What extrinsics calibration found.
#[derive(Clone, Debug)]
pub struct Extrinsics {
    pub calibration: RigCalibration,
    pub depth: CameraReport,
    pub color: CameraReport,
    /// The grey views with the board's axes drawn (x red, y green, z blue), as PNG.
    pub depth_axes_png: Vec<u8>,
    pub color_axes_png: Vec<u8>,
}

fn report(image: &Path, pose: &CameraPose, up: bool) -> CameraReport {
    let t = pose.world_from_camera.translation.vector;
    let q = pose.world_from_camera.rotation;
    let r = q.scaled_axis();
    let axis = pose.world_from_camera.rotation * Vector3::z();
    let vertical = if up { Vector3::z() } else { -Vector3::z() };
    CameraReport {
        image: image.display().to_string(),
        translation_mm: [t.x, t.y, t.z],
        rotation_quaternion_wxyz: [q.w, q.i, q.j, q.k],
        rotation_vector: [r.x, r.y, r.z],
        reprojection_rms_px: pose.rms_px,
        reprojection_max_px: pose.max_px,
        tilt_deg: axis.dot(&vertical).clamp(-1.0, 1.0).acos().to_degrees(),
    }
}

/// Finds the board in one view and poses the camera in the board's (the world's) frame.
fn pose_view(
    view: &ExtrinsicsView,
    board: &Board,
    role: CameraRole,
) -> Result<(CameraPose, Vec<u8>), CalibrationError> {
    let grey = read_grey(&view.image)?;
    let (w, h) = (grey.width(), grey.height());
    if (w, h) != (view.intrinsics.width, view.intrinsics.height) {
        return Err(ExtrinsicsError::SizeMismatch {
            role,
            image: view.image.clone(),
            image_w: w,
            image_h: h,
            intrinsics: view.intrinsics_file.clone(),
            w: view.intrinsics.width,
            h: view.intrinsics.height,
        }
        .into());
    }
    let detected = board
        .find_corners(&grey, &view.image)?
        .ok_or_else(|| super::BoardError::NotFound {
            image: view.image.clone(),
            board: *board,
        })?;
    let side = match role {
        CameraRole::Depth => Side::Front,
        CameraRole::Color => Side::Back,
    };
    let ordered = board.physical_order(&detected, &grey, side, &view.image)?;
    let pose = solve_pose(&board.object_points(), &ordered, &view.intrinsics)?;
    let centre_z = pose.world_from_camera.translation.vector.z;
    let (above, expected) = match role {
        CameraRole::Depth => (true, "above"),
        CameraRole::Color => (false, "below"),
    };
    if (centre_z > 0.0) != above {
        return Err(ExtrinsicsError::WrongSide {
            role,
            image: view.image.clone(),
            side: if centre_z > 0.0 { "above" } else { "below" },
            expected,
        }
        .into());
    }
    let png = axes_png(&grey, &view.intrinsics, &pose, board)?;
    Ok((pose, png))
}

/// The grey view in colour with the board's axes drawn, three squares long, encoded as PNG.
fn axes_png(
    grey: &GreyPicture,
    intrinsics: &Intrinsics,
    pose: &CameraPose,
    board: &Board,
) -> Result<Vec<u8>, CalibrationError> {
    let camera_from_world = pose.world_from_camera.inverse();
    let axes = opencv_calib::Pose {
        rvec: array3(&camera_from_world.rotation.scaled_axis()),
        tvec: array3(&camera_from_world.translation.vector),
    };
    let thickness = (intrinsics.width / 320).max(2) as i32;
    // Mark corner (0, 0) so a reader sees which corner the frame starts from.
    let first = board.corner_mm(0, 0);
    let mark = intrinsics
        .project(&(camera_from_world * first))
        .map(|p| opencv_calib::Circle {
            centre: [p.x.round() as i32, p.y.round() as i32],
            radius: thickness * 3,
            colour_bgr: [0.0, 200.0, 255.0],
            thickness,
        });
    let bgr = opencv_calib::draw_frame_axes(
        grey.view(),
        &camera_matrix(intrinsics),
        &intrinsics.distortion,
        &axes,
        (3.0 * board.square_mm) as f32,
        thickness,
        mark.as_ref(),
    )
    .map_err(cv_err("draw the axes"))?;
    let picture = RgbImage {
        width: grey.width(),
        height: grey.height(),
        data: bgr.chunks_exact(3).flat_map(|p| [p[2], p[1], p[0]]).collect(),
    };
    picture.to_png().map_err(CalibrationError::Png)
}

/// Poses both cameras against one board lying on the glass and returns the rig calibration.
///
/// # Errors
/// An unreadable image, an image whose size is not its intrinsics', no board found, a board
/// whose orientation cannot be told, a camera on the wrong side of the glass, or OpenCV failing.
pub fn calibrate_extrinsics(
    depth: &ExtrinsicsView,
    color: &ExtrinsicsView,
    board: &Board,
) -> Result<Extrinsics, CalibrationError> {
    board.check_orientable()?;
    let (d, depth_axes_png) = pose_view(depth, board, CameraRole::Depth)?;
    let (c, color_axes_png) = pose_view(color, board, CameraRole::Color)?;
    let cam = |v: &ExtrinsicsView, p: &CameraPose| CameraCalibration {
        intrinsics: v.intrinsics,
        world_from_camera: p.world_from_camera,
        reprojection_rms_px: p.rms_px,
        serial: v.serial.clone(),
    };
    Ok(Extrinsics {
        calibration: RigCalibration {
            depth: cam(depth, &d),
            color: cam(color, &c),
            board: Some(*board),
            source: None,
        },
        depth: report(&depth.image, &d, false),
        color: report(&color.image, &c, true),
        depth_axes_png,
        color_axes_png,
    })
}

/// Position and angle between two poses: millimetres between the centres, degrees of the
/// relative rotation.
pub fn pose_difference(a: &Isometry3<f64>, b: &Isometry3<f64>) -> (f64, f64) {
    let d = a.inverse() * b;
    (
        (a.translation.vector - b.translation.vector).norm(),
        d.rotation.angle().to_degrees(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::geometry::Rig;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    #[test]
    fn pnp_recovers_a_known_pose() {
        let rig = Rig::default_rig();
        let board = Board::parse("9x6", 20.0).expect("board");
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let noise = Normal::new(0.0, 0.05).expect("sigma");
        for camera in [rig.depth, rig.color] {
            let object = board.object_points();
            let image: Vec<Point2<f64>> = object
                .iter()
                .map(|p| {
                    let q = camera.project_world(p).expect("in front");
                    Point2::new(q.x + noise.sample(&mut rng), q.y + noise.sample(&mut rng))
                })
                .collect();
            let pose = solve_pose(&object, &image, &camera.intrinsics).expect("solves");
            let (mm, deg) = pose_difference(&pose.world_from_camera, &camera.world_from_camera);
            assert!(mm < 1.0 && deg < 0.2, "{mm} mm, {deg} deg");
            assert!(pose.rms_px < 0.2, "rms {}", pose.rms_px);
        }
    }

    #[test]
    fn pnp_refuses_too_few_points() {
        let i = Rig::default_rig().depth.intrinsics;
        assert!(solve_pose(&[Point3::origin()], &[Point2::origin()], &i).is_err());
    }
}
