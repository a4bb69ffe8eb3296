//! The floor ([`FloorPlane`]) and its fit to a background's readings: RANSAC over a
//! subsample of them, trying only planes that face the camera from far enough away, then least
//! squares over the inliers. The fit is deterministic (a fixed seed).

use super::SegmentError;
use nalgebra::{Matrix3, Point3, SymmetricEigen, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// Random plane hypotheses tried when fitting the floor.
const RANSAC_ITERATIONS: usize = 128;
/// Background pixels used to fit the floor (a regular subsample when there are more).
const FLOOR_SAMPLES: usize = 20_000;
/// Of those, the ones used to score a hypothesis.
const FLOOR_SCORE_SAMPLES: usize = 2_000;
/// The floor's normal must lie within this angle of the camera's line of sight to it (the
/// camera looks down at the floor; a wall seen at a grazing angle is never taken for it).
const FLOOR_MAX_TILT_DEG: f64 = 60.0;
/// The floor lies at least this far (mm) from the camera.
const MIN_FLOOR_DISTANCE_MM: f64 = 100.0;
/// The floor must hold at least this fraction of the background's readings.
const FLOOR_MIN_INLIERS: f64 = 0.2;

/// The floor: `height_mm(p) = normal . p + offset_mm` for a point `p` in the camera frame, with
/// `normal` a unit vector pointing up (towards the camera), so the camera is `offset_mm` above
/// the floor.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FloorPlane {
    pub normal: Vector3<f64>,
    pub offset_mm: f64,
}

impl FloorPlane {
    /// The height (mm) of a camera-frame point above the floor.
    pub fn height_mm(&self, p: &Point3<f64>) -> f64 {
        self.normal.dot(&p.coords) + self.offset_mm
    }
}

/// The least-squares plane through `points` (`normal . p + offset = 0`, the normal oriented
/// towards the camera), or `None` when they do not span a plane.
fn plane_through(points: &[Vector3<f64>]) -> Option<FloorPlane> {
    if points.len() < 3 {
        return None;
    }
    let mean = points.iter().sum::<Vector3<f64>>() / points.len() as f64;
    let mut cov = Matrix3::zeros();
    for p in points {
        let d = p - mean;
        cov += d * d.transpose();
    }
    let eig = SymmetricEigen::new(cov);
    let k = eig.eigenvalues.imin();
    let normal = eig.eigenvectors.column(k).into_owned();
    oriented(normal, mean)
}

/// The plane with `normal` through `point`, its normal turned towards the camera (the origin);
/// `None` for a degenerate normal or a plane through the camera.
fn oriented(normal: Vector3<f64>, point: Vector3<f64>) -> Option<FloorPlane> {
    let len = normal.norm();
    if !len.is_finite() || len <= 1e-9 {
        return None;
    }
    let mut n = normal / len;
    let mut c = -n.dot(&point);
    if c < 0.0 {
        n = -n;
        c = -c;
    }
    (c > 1e-6).then_some(FloorPlane {
        normal: n,
        offset_mm: c,
    })
}

/// Fits the floor to a background: RANSAC over a subsample of its readings, then least
/// squares over the inliers. Deterministic (a fixed seed).
pub(super) fn fit_floor(depth: &[f32], rays: &[[f32; 2]], tolerance: f64) -> Result<FloorPlane, SegmentError> {
    let valid = depth.iter().filter(|&&z| z > 0.0).count();
    if valid < 3 {
        return Err(SegmentError::Floor {
            reason: format!("only {valid} pixels have a reading"),
        });
    }
    let stride = valid.div_ceil(FLOOR_SAMPLES).max(1);
    let points: Vec<Vector3<f64>> = depth
        .iter()
        .zip(rays)
        .filter(|(z, _)| **z > 0.0)
        .step_by(stride)
        .map(|(&z, r)| Vector3::new(f64::from(r[0]), f64::from(r[1]), 1.0) * f64::from(z))
        .collect();
    let score_stride = points.len().div_ceil(FLOOR_SCORE_SAMPLES).max(1);
    let scoring: Vec<Vector3<f64>> = points.iter().step_by(score_stride).copied().collect();
    let min_facing = FLOOR_MAX_TILT_DEG.to_radians().cos();
    // The camera looks down at the floor: along the mean ray to the readings, the floor's
    // normal (pointing up, towards the camera) is seen nearly head-on, and the floor is not
    // right at the camera.
    let sight = points.iter().map(|p| p.normalize()).sum::<Vector3<f64>>().normalize();
    let faces_camera = |p: &FloorPlane| -p.normal.dot(&sight) >= min_facing && p.offset_mm >= MIN_FLOOR_DISTANCE_MM;
    let inliers = |plane: &FloorPlane, pts: &[Vector3<f64>]| {
        pts.iter()
            .filter(|p| (plane.normal.dot(p) + plane.offset_mm).abs() <= tolerance)
            .count()
    };
    let mut rng = ChaCha8Rng::seed_from_u64(0x00F1_0012);
    let mut best: Option<(usize, FloorPlane)> = None;
    for _ in 0..RANSAC_ITERATIONS {
        let [a, b, c] = [0; 3].map(|_| points[rng.gen_range(0..points.len())]);
        let Some(plane) = oriented((b - a).cross(&(c - a)), a) else {
            continue;
        };
        if !faces_camera(&plane) {
            continue;
        }
        let score = inliers(&plane, &scoring);
        if best.is_none_or(|(s, _)| score > s) {
            best = Some((score, plane));
        }
    }
    let Some((_, mut plane)) = best else {
        return Err(SegmentError::Floor {
            reason: "no plane facing the camera".to_owned(),
        });
    };
    let mut support = Vec::with_capacity(points.len());
    for _ in 0..3 {
        support.clear();
        support.extend(
            points
                .iter()
                .filter(|p| (plane.normal.dot(p) + plane.offset_mm).abs() <= tolerance),
        );
        match plane_through(&support) {
            Some(p) if faces_camera(&p) => plane = p,
            _ => break,
        }
    }
    let count = inliers(&plane, &points);
    if (count as f64) < FLOOR_MIN_INLIERS * points.len() as f64 {
        return Err(SegmentError::Floor {
            reason: format!(
                "the best plane holds {count} of {} sampled readings, fewer than a fifth",
                points.len()
            ),
        });
    }
    Ok(plane)
}
