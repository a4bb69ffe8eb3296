//! The floor ([`FloorPlane`]) and its fit to a background's readings: RANSAC over a
//! subsample of them, trying only planes that face the camera from far enough away, then least
//! squares over the inliers. The fit is deterministic (a fixed seed).

use super::SegmentError;
use crate::core::geometry::Camera;
use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, SymmetricEigen, Translation3, UnitQuaternion, Vector3};
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
pub(super) const FLOOR_MIN_INLIERS: f64 = 0.2;

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

    /// The floor of a posed camera: the world's `z = 0` plane in the camera's frame.
    pub fn of_camera(camera: &Camera) -> Self {
        let camera_from_world = camera.camera_from_world();
        let normal = camera_from_world.rotation * Vector3::z();
        let origin = camera_from_world * Point3::origin();
        Self {
            normal,
            offset_mm: -normal.dot(&origin.coords),
        }
    }

    /// How high the camera's centre is above the floor (mm).
    pub fn camera_height_mm(&self) -> f64 {
        self.offset_mm
    }

    /// The angle between the camera's optical axis and the floor's downward normal (degrees):
    /// 0 for a camera looking straight down.
    pub fn camera_tilt_deg(&self) -> f64 {
        (-self.normal.z).clamp(-1.0, 1.0).acos().to_degrees()
    }

    /// The depth (mm along the optical axis) at which the floor is seen along a pixel's ray
    /// `(x, y, 1)`, or `None` when the ray never meets it.
    pub fn depth_along(&self, ray: &Vector3<f64>) -> Option<f64> {
        let a = self.normal.dot(ray);
        (a < -1e-9).then(|| -self.offset_mm / a)
    }

    /// The camera's pose in a world frame made from this floor alone: z up from the floor
    /// (so a point's z is its height above it), the origin where the optical axis meets the
    /// floor, x along the image's x axis laid on the floor. This is the world frame of a
    /// recording without a rig calibration.
    pub fn world_from_camera(&self) -> Isometry3<f64> {
        let z = self.normal;
        let along = Vector3::x() - z * z.x;
        let x = if along.norm() > 1e-9 {
            along.normalize()
        } else {
            (Vector3::y() - z * z.y).normalize()
        };
        let y = z.cross(&x);
        // The columns are the world's axes in the camera frame.
        let camera_from_world_rotation = Rotation3::from_basis_unchecked(&[x, y, z]);
        let origin = self
            .depth_along(&Vector3::z())
            .map_or_else(|| -z * self.offset_mm, |t| Vector3::z() * t);
        let camera_from_world = Isometry3::from_parts(
            Translation3::from(origin),
            UnitQuaternion::from_rotation_matrix(&camera_from_world_rotation),
        );
        camera_from_world.inverse()
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
/// Keeps `plane` as a search's best when it scores more than the best so far.
fn keep_better(best: &mut Option<(usize, FloorPlane)>, plane: FloorPlane, score: usize) {
    if best.is_none_or(|(s, _)| score > s) {
        *best = Some((score, plane));
    }
}

/// The best plane a search found (by its score), fitted again three times to the points
/// within `tolerance` of it while the fit still faces the camera.
fn refined(
    best: Option<(usize, FloorPlane)>,
    points: &[Vector3<f64>],
    tolerance: f64,
    faces_camera: impl Fn(&FloorPlane) -> bool,
) -> Result<FloorPlane, SegmentError> {
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
    Ok(plane)
}

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

/// Fits the floor to a background: RANSAC over a subsample of its readings (those inside
/// `mask` when one is given, 1 = inside), then least squares over the inliers.
/// Deterministic (a fixed seed).
///
/// # Errors
/// Fewer than three readings, no plane facing the camera, or a plane holding fewer than a
/// fifth of the readings.
pub(super) fn fit_floor(
    depth: &[f32],
    rays: &[[f32; 2]],
    tolerance: f64,
    mask: Option<&[u8]>,
) -> Result<FloorPlane, SegmentError> {
    let (plane, count, total) = best_plane(depth, rays, tolerance, mask)?;
    if (count as f64) < FLOOR_MIN_INLIERS * total as f64 {
        return Err(SegmentError::Floor {
            reason: format!("the best plane holds {count} of {total} sampled readings, fewer than a fifth"),
        });
    }
    Ok(plane)
}

/// The plane holding the most readings (inside `mask`), facing the camera, with how many of
/// the sampled readings it holds and how many were sampled.
pub(super) fn best_plane(
    depth: &[f32],
    rays: &[[f32; 2]],
    tolerance: f64,
    mask: Option<&[u8]>,
) -> Result<(FloorPlane, usize, usize), SegmentError> {
    let inside = |i: usize| mask.is_none_or(|m| m.get(i).is_some_and(|&v| v != 0));
    let valid = depth.iter().enumerate().filter(|&(i, &z)| z > 0.0 && inside(i)).count();
    if valid < 3 {
        return Err(SegmentError::Floor {
            reason: format!("only {valid} pixels have a reading"),
        });
    }
    let stride = valid.div_ceil(FLOOR_SAMPLES).max(1);
    let points: Vec<Vector3<f64>> = depth
        .iter()
        .zip(rays)
        .enumerate()
        .filter(|&(i, (z, _))| *z > 0.0 && inside(i))
        .step_by(stride)
        .map(|(_, (&z, r))| Vector3::new(f64::from(r[0]), f64::from(r[1]), 1.0) * f64::from(z))
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
        if faces_camera(&plane) {
            keep_better(&mut best, plane, inliers(&plane, &scoring));
        }
    }
    let plane = refined(best, &points, tolerance, faces_camera)?;
    let count = inliers(&plane, &points);
    Ok((plane, count, points.len()))
}

/// Of a local hypothesis's three readings, the second and third lie within this many pixels
/// of the first (in both directions).
const LOCAL_WINDOW_PX: usize = 20;

/// Like [`best_plane`] over the readings inside `mask` (1 = inside) of an image `width`
/// pixels wide, with each hypothesis drawn from three readings near each other, so that a
/// plane holding a small share of them (an arena a tenth of the view) is drawn about as
/// often as its share, rather than its share cubed. `round` varies the seed.
///
/// # Errors
/// Fewer than three readings, or no plane facing the camera.
pub(super) fn best_plane_local(
    depth: &[f32],
    rays: &[[f32; 2]],
    width: usize,
    tolerance: f64,
    mask: &[u8],
    round: u64,
) -> Result<FloorPlane, SegmentError> {
    let inside = |i: usize| mask.get(i).is_some_and(|&v| v != 0) && depth.get(i).is_some_and(|&z| z > 0.0);
    let candidates: Vec<usize> = (0..depth.len()).filter(|&i| inside(i)).collect();
    if candidates.len() < 3 || width == 0 {
        return Err(SegmentError::Floor {
            reason: format!("only {} pixels have a reading", candidates.len()),
        });
    }
    let point = |i: usize| {
        let r = rays[i];
        Vector3::new(f64::from(r[0]), f64::from(r[1]), 1.0) * f64::from(depth[i])
    };
    let stride = candidates.len().div_ceil(FLOOR_SAMPLES).max(1);
    let points: Vec<Vector3<f64>> = candidates.iter().step_by(stride).map(|&i| point(i)).collect();
    let score_stride = points.len().div_ceil(FLOOR_SCORE_SAMPLES).max(1);
    let scoring: Vec<Vector3<f64>> = points.iter().step_by(score_stride).copied().collect();
    let min_facing = FLOOR_MAX_TILT_DEG.to_radians().cos();
    let sight = points.iter().map(|p| p.normalize()).sum::<Vector3<f64>>().normalize();
    let faces_camera = |p: &FloorPlane| -p.normal.dot(&sight) >= min_facing && p.offset_mm >= MIN_FLOOR_DISTANCE_MM;
    let inliers = |plane: &FloorPlane, pts: &[Vector3<f64>]| {
        pts.iter()
            .filter(|p| (plane.normal.dot(p) + plane.offset_mm).abs() <= tolerance)
            .count()
    };
    let height = depth.len() / width;
    let mut rng = ChaCha8Rng::seed_from_u64(0x10CA_1000 + round);
    let mut best: Option<(usize, FloorPlane)> = None;
    for _ in 0..2 * RANSAC_ITERATIONS {
        let first = candidates[rng.gen_range(0..candidates.len())];
        let (x, y) = (first % width, first / width);
        let mut near = || {
            let nx = rng.gen_range(x.saturating_sub(LOCAL_WINDOW_PX)..(x + LOCAL_WINDOW_PX + 1).min(width));
            let ny = rng.gen_range(y.saturating_sub(LOCAL_WINDOW_PX)..(y + LOCAL_WINDOW_PX + 1).min(height));
            let i = ny * width + nx;
            inside(i).then(|| point(i))
        };
        let (Some(b), Some(c)) = (near(), near()) else {
            continue;
        };
        let a = point(first);
        let Some(plane) = oriented((b - a).cross(&(c - a)), a) else {
            continue;
        };
        if faces_camera(&plane) {
            keep_better(&mut best, plane, inliers(&plane, &scoring));
        }
    }
    refined(best, &points, tolerance, faces_camera)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::geometry::{Rig, look_at};

    #[test]
    fn a_floor_gives_back_the_camera_height_and_tilt_and_heights_as_world_z() {
        for (height, tilt_deg) in [(550.0, 0.0), (670.0, 8.0), (800.0, 15.0)] {
            let t = f64::to_radians(tilt_deg);
            let mut camera = Rig::default_rig().depth;
            camera.world_from_camera = look_at(
                Point3::new(30.0, -20.0, height),
                Point3::new(30.0 + height * t.tan(), -20.0, 0.0),
                -Vector3::y(),
            );
            let floor = FloorPlane::of_camera(&camera);
            assert!((floor.camera_height_mm() - height).abs() < 1e-9);
            assert!((floor.camera_tilt_deg() - tilt_deg).abs() < 1e-9);
            let world = floor.world_from_camera();
            // Any camera-frame point: its world z is its height above the floor.
            for p in [Point3::new(10.0, 20.0, 500.0), Point3::new(-80.0, 40.0, height)] {
                let z_world = (world * p).z;
                let truth = (camera.world_from_camera * p).z;
                assert!((z_world - truth).abs() < 1e-9, "{z_world} vs {truth}");
                assert!((z_world - floor.height_mm(&p)).abs() < 1e-9);
            }
            assert!(((world * Point3::origin()).z - height).abs() < 1e-9);
        }
    }
}
