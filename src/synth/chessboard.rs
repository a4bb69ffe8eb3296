//! Rendered chessboard views for testing calibration end to end: intrinsics views of a board
//! held at random poses in front of each camera, and the extrinsics pair of one board lying
//! flat on the glass, seen from above by the depth camera's IR image and from below, through
//! the glass and the transparent film, by the colour camera (so mirrored).
//!
//! Each pixel is the mean of 16 rays (n-rooks: one per row and column of a 16x16 sub-grid) cast through the camera's own distortion model onto the
//! board plane, then blurred a little, lit by a gradient and given sensor noise. The glass is
//! treated as infinitely thin (no refraction). Output is deterministic for a seed.

use crate::core::geometry::{Camera, Intrinsics, Rig};
use crate::vision::calibrate::{Board, RigCalibration};
use nalgebra::{Isometry3, Point2, Point3, Translation3, UnitQuaternion, Vector3};
use rand::Rng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// What `synth chessboard` renders.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChessboardSpec {
    pub board: Board,
    /// Intrinsics views per camera.
    pub views: u32,
    pub seed: u64,
    /// Binning of the colour camera's sensor (1, 2 or 4).
    pub color_binning: u32,
}

/// Directory and file names of a chessboard set.
pub const COLOR_DIR: &str = "color";
pub const DEPTH_IR_DIR: &str = "depth-ir";
pub const EXTRINSICS_DIR: &str = "extrinsics";
pub const TRUTH_FILE: &str = "truth.yaml";

/// Errors writing a chessboard set.
#[derive(Debug, thiserror::Error)]
pub enum ChessboardError {
    #[error("cannot write {path:?}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot encode PNG {path:?}")]
    Png {
        path: PathBuf,
        #[source]
        source: png::EncodingError,
    },
    #[error("the {board} board with {square_mm} mm squares does not fit in the {camera} camera's view")]
    DoesNotFit {
        board: Board,
        square_mm: f64,
        camera: &'static str,
    },
    #[error("cannot write the true rig")]
    Truth(#[from] crate::vision::calibrate::CalibrationError),
}

/// A grey image.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GreyImage {
    pub width: u32,
    pub height: u32,
    pub data: Vec<u8>,
}

/// The white film around the checkered area, in squares.
const MARGIN_SQUARES: f64 = 1.0;

/// Reflectances of dark squares, light squares and film, and of the background beyond.
const DARK: f64 = 0.10;
const LIGHT: f64 = 0.88;
const BACKGROUND: f64 = 0.30;

/// Renders the board seen by a camera at `camera_from_board` (the board in its plane z = 0).
pub fn render_view(
    intrinsics: &Intrinsics,
    camera_from_board: &Isometry3<f64>,
    board: &Board,
    rng: &mut impl Rng,
) -> GreyImage {
    const SS: usize = 16;
    let (w, h) = (intrinsics.width as usize, intrinsics.height as usize);
    let board_from_camera = camera_from_board.inverse();
    let r = board_from_camera.rotation.to_rotation_matrix().into_inner();
    let o = board_from_camera.translation.vector;
    let (ex, ey) = board.extent_mm();
    let (half_x, half_y) = (
        ex / 2.0 + MARGIN_SQUARES * board.square_mm,
        ey / 2.0 + MARGIN_SQUARES * board.square_mm,
    );
    let mut reflect = vec![0.0f64; w * h];
    reflect.par_chunks_mut(w).enumerate().for_each(|(v, row)| {
        for (u, px) in row.iter_mut().enumerate() {
            let mut sum = 0.0;
            for k in 0..SS {
                {
                    // N-rooks samples: each at its own column and row of a 16x16 sub-grid, so
                    // edges near the pixel axes are not quantised to quarter pixels.
                    // Each sample is jittered inside its sub-cell, so that the coverage of a
                    // straight edge is not quantised the same way in every pixel along it.
                    let (sx, sy) = (k, (k * 5) % SS);
                    let (jx, jy) = jitter(u, v, k);
                    let pixel = Point2::new(
                        u as f64 + (sx as f64 + jx) / SS as f64 - 0.5,
                        v as f64 + (sy as f64 + jy) / SS as f64 - 0.5,
                    );
                    let d = r * intrinsics.ray(&pixel);
                    let t = -o.z / d.z;
                    if !t.is_finite() || t <= 0.0 {
                        sum += BACKGROUND;
                        continue;
                    }
                    let (x, y) = (o.x + t * d.x, o.y + t * d.y);
                    sum += match board.shade_at(x, y) {
                        Some(true) => DARK,
                        Some(false) => LIGHT,
                        None if x.abs() <= half_x && y.abs() <= half_y => LIGHT,
                        None => BACKGROUND,
                    };
                }
            }
            *px = sum / SS as f64;
        }
    });
    // Optical blur: a 3x3 binomial kernel twice (a point spread of about 1 pixel, as a real
    // lens gives; sharper edges lock corners to the pixel grid).
    let blurred = blur3(&blur3(&reflect, w, h), w, h);
    // Light falling off across the view, then sensor noise.
    let angle: f64 = rng.gen_range(0.0..std::f64::consts::TAU);
    let (gx, gy) = (angle.cos(), angle.sin());
    let strength: f64 = rng.gen_range(0.1..0.3);
    let gain: f64 = rng.gen_range(200.0..250.0);
    let noise = Normal::new(0.0, 2.0).expect("a positive standard deviation");
    let diag = ((w * w + h * h) as f64).sqrt();
    let mut data = Vec::with_capacity(w * h);
    for v in 0..h {
        for u in 0..w {
            let s = ((u as f64 - w as f64 / 2.0) * gx + (v as f64 - h as f64 / 2.0) * gy) / diag;
            let light = 1.0 - strength * (0.5 - s);
            let value = blurred[v * w + u] * light * gain + noise.sample(rng);
            data.push(value.round().clamp(0.0, 255.0) as u8);
        }
    }
    GreyImage {
        width: intrinsics.width,
        height: intrinsics.height,
        data,
    }
}

/// Two numbers in [0, 1) from a pixel and a sample index: a fixed hash, so renders are the same
/// whatever the thread count.
fn jitter(u: usize, v: usize, k: usize) -> (f64, f64) {
    let mut x = (u as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (v as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ (k as u64).wrapping_mul(0x1656_67B1_9E37_79F9);
    x ^= x >> 33;
    x = x.wrapping_mul(0xFF51_AFD7_ED55_8CCD);
    x ^= x >> 33;
    x = x.wrapping_mul(0xC4CE_B9FE_1A85_EC53);
    x ^= x >> 33;
    let a = (x >> 40) as f64 / (1u64 << 24) as f64;
    let b = ((x >> 16) & 0xFF_FFFF) as f64 / (1u64 << 24) as f64;
    (a, b)
}

fn blur3(src: &[f64], w: usize, h: usize) -> Vec<f64> {
    let k = [0.25, 0.5, 0.25];
    let mut tmp = vec![0.0; w * h];
    for v in 0..h {
        for u in 0..w {
            let mut s = 0.0;
            for (i, kk) in k.iter().enumerate() {
                let uu = (u + i).saturating_sub(1).min(w - 1);
                s += kk * src[v * w + uu];
            }
            tmp[v * w + u] = s;
        }
    }
    let mut out = vec![0.0; w * h];
    for v in 0..h {
        for u in 0..w {
            let mut s = 0.0;
            for (i, kk) in k.iter().enumerate() {
                let vv = (v + i).saturating_sub(1).min(h - 1);
                s += kk * tmp[vv * w + u];
            }
            out[v * w + u] = s;
        }
    }
    out
}

/// The corners of the board's film (checkered area and margin) in the board frame.
fn film_corners(board: &Board) -> [Point3<f64>; 4] {
    let (ex, ey) = board.extent_mm();
    let (hx, hy) = (
        ex / 2.0 + MARGIN_SQUARES * board.square_mm,
        ey / 2.0 + MARGIN_SQUARES * board.square_mm,
    );
    [
        Point3::new(-hx, -hy, 0.0),
        Point3::new(hx, -hy, 0.0),
        Point3::new(hx, hy, 0.0),
        Point3::new(-hx, hy, 0.0),
    ]
}

/// A random pose of a hand-held board in front of a camera: tilted 15-40 degrees, turned
/// up to 45 degrees in the image plane, filling 45-80 % of the image's width, wholly in view.
pub fn random_board_pose(intrinsics: &Intrinsics, board: &Board, rng: &mut impl Rng) -> Option<Isometry3<f64>> {
    let (ex, _) = board.extent_mm();
    let film_w = ex + 2.0 * MARGIN_SQUARES * board.square_mm;
    let margin_px = 6.0;
    for _ in 0..500 {
        let fill: f64 = rng.gen_range(0.45..0.8);
        let distance = film_w * intrinsics.fx / (fill * f64::from(intrinsics.width));
        // Facing the camera: board x along image x, board y along image -y, z towards the camera.
        let facing = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
        let spin = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), rng.gen_range(-45f64..45.0).to_radians());
        let axis_angle: f64 = rng.gen_range(0.0..std::f64::consts::TAU);
        let tilt_axis = nalgebra::Unit::new_normalize(Vector3::new(axis_angle.cos(), axis_angle.sin(), 0.0));
        let tilt = UnitQuaternion::from_axis_angle(&tilt_axis, rng.gen_range(15f64..40.0).to_radians());
        let rotation = tilt * spin * facing;
        let centre_px = Point2::new(
            rng.gen_range(0.2..0.8) * f64::from(intrinsics.width),
            rng.gen_range(0.2..0.8) * f64::from(intrinsics.height),
        );
        let centre = intrinsics.unproject(&centre_px, distance);
        let pose = Isometry3::from_parts(Translation3::from(centre.coords), rotation);
        let inside = film_corners(board).iter().all(|c| {
            intrinsics.project(&(pose * c)).is_some_and(|p| {
                p.x >= margin_px
                    && p.y >= margin_px
                    && p.x <= f64::from(intrinsics.width) - 1.0 - margin_px
                    && p.y <= f64::from(intrinsics.height) - 1.0 - margin_px
            })
        });
        if inside {
            return Some(pose);
        }
    }
    None
}

fn fits(camera: &Camera, board: &Board) -> bool {
    film_corners(board)
        .iter()
        .all(|c| camera.project_world(c).is_some_and(|p| camera.intrinsics.contains(&p)))
}

/// Writes an 8-bit grey PNG.
///
/// # Errors
/// The file cannot be created or encoded.
pub fn write_grey_png(path: &Path, image: &GreyImage) -> Result<(), ChessboardError> {
    let file = std::fs::File::create(path).map_err(|source| ChessboardError::Io {
        path: path.to_owned(),
        source,
    })?;
    let png_err = |source| ChessboardError::Png {
        path: path.to_owned(),
        source,
    };
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), image.width, image.height);
    enc.set_color(png::ColorType::Grayscale);
    enc.set_depth(png::BitDepth::Eight);
    let mut writer = enc.write_header().map_err(png_err)?;
    writer.write_image_data(&image.data).map_err(png_err)?;
    writer.finish().map_err(png_err)
}

/// Renders a full chessboard set into `dir` (which must exist): `color/view-NN.png`,
/// `depth-ir/view-NN.png`, `extrinsics/{color,depth-ir}.png` and `truth.yaml`. `done` is
/// called with the number of images written so far.
///
/// # Errors
/// A board too large for a camera's view, or a file that cannot be written.
pub fn write_chessboards(
    dir: &Path,
    rig: &Rig,
    spec: &ChessboardSpec,
    mut done: impl FnMut(u64),
) -> Result<(), ChessboardError> {
    let board = &spec.board;
    let mkdir = |p: PathBuf| -> Result<PathBuf, ChessboardError> {
        std::fs::create_dir_all(&p).map_err(|source| ChessboardError::Io {
            path: p.clone(),
            source,
        })?;
        Ok(p)
    };
    let mut count = 0;
    for (stream, name, camera) in [(1u64, COLOR_DIR, &rig.color), (2, DEPTH_IR_DIR, &rig.depth)] {
        let sub = mkdir(dir.join(name))?;
        for view in 0..spec.views {
            let mut rng = crate::core::rng::item_rng(spec.seed, 0xC4E5 + stream, u64::from(view));
            let pose = random_board_pose(&camera.intrinsics, board, &mut rng).ok_or(ChessboardError::DoesNotFit {
                board: *board,
                square_mm: board.square_mm,
                camera: if stream == 1 { "colour" } else { "depth" },
            })?;
            let image = render_view(&camera.intrinsics, &pose, board, &mut rng);
            write_grey_png(&sub.join(format!("view-{view:02}.png")), &image)?;
            count += 1;
            done(count);
        }
    }
    // The extrinsics pair: the board on the glass, its frame the world frame.
    let sub = mkdir(dir.join(EXTRINSICS_DIR))?;
    for (stream, name, camera) in [(3u64, "color.png", &rig.color), (4, "depth-ir.png", &rig.depth)] {
        if !fits(camera, board) {
            return Err(ChessboardError::DoesNotFit {
                board: *board,
                square_mm: board.square_mm,
                camera: if stream == 3 { "colour" } else { "depth" },
            });
        }
        let mut rng = crate::core::rng::item_rng(spec.seed, 0xC4E5 + stream, 0);
        let image = render_view(&camera.intrinsics, &camera.camera_from_world(), board, &mut rng);
        write_grey_png(&sub.join(name), &image)?;
        count += 1;
        done(count);
    }
    let mut truth = RigCalibration::from_rig(rig);
    truth.board = Some(*board);
    truth.save(&dir.join(TRUTH_FILE))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::rng::item_rng;
    use crate::vision::calibrate::board::{GreyPicture, Side};

    #[test]
    fn extrinsics_views_are_found_in_physical_order() {
        let rig = Rig::default_rig().with_color_binning(2);
        let board = Board::parse("9x6", 20.0).expect("board");
        for (camera, side) in [(&rig.depth, Side::Front), (&rig.color, Side::Back)] {
            let mut rng = item_rng(1, 2, 3);
            let img = render_view(&camera.intrinsics, &camera.camera_from_world(), &board, &mut rng);
            let grey = GreyPicture::new(img.width, img.height, img.data.clone()).expect("picture");
            let path = Path::new("rendered");
            let found = board.find_corners(&grey, path).expect("runs").expect("board found");
            let ordered = board.physical_order(&found, &grey, side, path).expect("ordered");
            let mut mean = nalgebra::Vector2::zeros();
            let mut sq = 0.0;
            for (p, obj) in ordered.iter().zip(board.object_points()) {
                let truth = camera.project_world(&obj).expect("in front");
                assert!((p - truth).norm() < 0.3, "{side:?}: {p} vs {truth}");
                mean += p - truth;
                sq += (p - truth).norm_squared();
            }
            let n = ordered.len() as f64;
            assert!((mean / n).norm() < 0.05, "{side:?}: mean offset {}", mean / n);
            assert!((sq / n).sqrt() < 0.08, "{side:?}: rms {}", (sq / n).sqrt());
        }
    }
}
