//! Inverse kinematics of the limbs: the two-bone solver both the synthesis engine and the
//! fusion stage use, and the hind-limb rule of the paper (the knee-ankle-paw angle fixed).

use nalgebra::{Point3, Rotation3, Vector3};

/// The middle joint of a two-bone chain from `root` to `target` with bone lengths `upper` and
/// `lower`, bending towards `pole` (a direction, not a point).
///
/// Unreachable targets are clamped: too far, the chain points straight at the target; too
/// close, it folds as far as the lengths allow. The result is always finite when the inputs
/// are, and the returned end point is where the chain's tip really is.
pub fn two_bone(
    root: &Point3<f64>,
    target: &Point3<f64>,
    upper: f64,
    lower: f64,
    pole: &Vector3<f64>,
) -> (Point3<f64>, Point3<f64>) {
    let to_target = target - root;
    let distance = to_target.norm();
    let axis = if distance > 1e-9 {
        to_target / distance
    } else {
        // Target on the root: any axis orthogonal to the pole will do.
        any_orthogonal(pole)
    };
    let reach_max = upper + lower;
    let reach_min = (upper - lower).abs();
    let d = distance.clamp(reach_min.max(1e-6), reach_max.max(1e-6));
    // Law of cosines: angle at the root between the axis and the upper bone.
    let cos_a = ((upper * upper + d * d - lower * lower) / (2.0 * upper * d)).clamp(-1.0, 1.0);
    let sin_a = (1.0 - cos_a * cos_a).max(0.0).sqrt();
    let bend = {
        let p = pole - axis * axis.dot(pole);
        if p.norm() > 1e-9 {
            p.normalize()
        } else {
            any_orthogonal(&axis)
        }
    };
    let middle = root + (axis * cos_a + bend * sin_a) * upper;
    let end = root + axis * d;
    (middle, end)
}

/// A unit vector orthogonal to `v` (or the x axis when `v` is zero).
pub fn any_orthogonal(v: &Vector3<f64>) -> Vector3<f64> {
    let n = v.norm();
    if n < 1e-12 {
        return Vector3::x();
    }
    let u = v / n;
    let helper = if u.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    u.cross(&helper).normalize()
}

/// Fore limb from the shoulder to a paw: the wrist sits behind and above the paw at the paw's
/// length, and the elbow bends backwards (two-bone IK with the upper arm and forearm).
///
/// `forward` is the body's horizontal forward direction and `up` the world's up. Returns
/// `(elbow, wrist)`.
pub fn fore_limb(
    shoulder: &Point3<f64>,
    paw: &Point3<f64>,
    [upper_arm, forearm, paw_length]: [f64; 3],
    forward: &Vector3<f64>,
    up: &Vector3<f64>,
) -> (Point3<f64>, Point3<f64>) {
    let wrist_dir = (-forward * 0.55 + up).normalize();
    let wrist_target = paw + wrist_dir * paw_length;
    two_bone(shoulder, &wrist_target, upper_arm, forearm, &(-forward + up * 0.3))
}

/// Where a paw rests when the limb stands in its neutral stance: on the floor (its joint
/// `sole_mm` up) under its root (shoulder or hip), a little ahead for fore paws and behind
/// for hind paws, and a little outward. `forward` is horizontal, `scale` the mouse's size
/// factor, `side_sign` +1 for left and -1 for right.
pub fn stance_paw(
    root: &Point3<f64>,
    forward: &Vector3<f64>,
    side_sign: f64,
    fore: bool,
    scale: f64,
    sole_mm: f64,
) -> Point3<f64> {
    let left = Vector3::z().cross(forward);
    Point3::new(root.x, root.y, sole_mm * scale)
        + forward * if fore { scale } else { -scale }
        + left * side_sign * 2.0 * scale
}

/// Where a fore paw is held when the mouse rears: in front of the chest, below and ahead of
/// its shoulder in the withers' frame (x forward along the spine, y left, z dorsal).
pub fn chest_paw(shoulder: &Point3<f64>, withers_frame: &Rotation3<f64>, side_sign: f64, scale: f64) -> Point3<f64> {
    shoulder + withers_frame * Vector3::new(7.0 * scale, side_sign * 2.5 * scale, -9.0 * scale)
}

/// Where a fore paw is held when the mouse grooms: at the face, behind and below the snout in
/// the head's frame.
pub fn face_paw(snout: &Point3<f64>, head_frame: &Rotation3<f64>, side_sign: f64, scale: f64) -> Point3<f64> {
    snout + head_frame * Vector3::new(-6.0 * scale, side_sign * 4.0 * scale, -4.0 * scale)
}

/// Hind limb from the hip to a paw on or near the floor, with the angle at the ankle between
/// knee and paw fixed at `ankle_angle` (the paper sets it to 90 degrees).
///
/// `forward` is the body's forward direction (the foot points along it and the knee bends
/// towards it) and `up` the world's up. Returns `(knee, ankle)`. The ankle is placed behind
/// the paw at the foot's length, in the vertical plane along `forward`, at the elevation that
/// lets the thigh reach it; when none does the closest is taken and the thigh is clamped by
/// [`two_bone`].
pub fn hind_limb(
    hip: &Point3<f64>,
    paw: &Point3<f64>,
    [thigh, shin, foot]: [f64; 3],
    ankle_angle: f64,
    forward: &Vector3<f64>,
    up: &Vector3<f64>,
) -> (Point3<f64>, Point3<f64>) {
    // The leg's plane: spanned by `up` and the body's forward direction (the foot points
    // forward from the ankle, the knee forward from the hip).
    let mut back = -forward;
    back -= up * up.dot(&back);
    let back = if back.norm() > 1e-6 {
        back.normalize()
    } else {
        any_orthogonal(up)
    };
    let knee_for = |elevation: f64| {
        let foot_dir = back * elevation.cos() + up * elevation.sin();
        let ankle = paw + foot_dir * foot;
        // The shin leaves the ankle at `ankle_angle` from the foot, turned forward and up.
        let from_paw = -foot_dir;
        let normal = from_paw.cross(up);
        let normal = if normal.norm() > 1e-9 {
            normal.normalize()
        } else {
            any_orthogonal(up)
        };
        let rot = Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(normal), -ankle_angle);
        let mut shin_dir = rot * from_paw;
        if shin_dir.dot(up) < 0.0 {
            shin_dir = Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(normal), ankle_angle) * from_paw;
        }
        let knee = ankle + shin_dir * shin;
        (knee, ankle)
    };
    // Scan the foot's elevation from flat upwards for the first ankle whose knee lies at thigh
    // length from the hip (the lowest heel, as a crouching mouse holds it).
    let mut best = (f64::INFINITY, 0.0);
    let steps = 90;
    for i in 0..=steps {
        let e = f64::from(i) / f64::from(steps) * 85f64.to_radians();
        let (knee, _) = knee_for(e);
        let err = ((knee - hip).norm() - thigh).abs();
        if err < best.0 {
            best = (err, e);
        }
        if err < 0.2 {
            break;
        }
    }
    let (_, ankle) = knee_for(best.1);
    // The knee bends forward and a little up, never down through the floor.
    let (knee, _) = two_bone(hip, &ankle, thigh, shin, &(forward + up * 0.5));
    (knee, ankle)
}

/// Radius of the paw's sole: a paw resting on the glass has its joint this high.
pub const PAW_SOLE_MM: f64 = 1.5;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_bone_reaches_reachable_targets() {
        let root = Point3::origin();
        let target = Point3::new(10.0, 0.0, 5.0);
        let (mid, end) = two_bone(&root, &target, 8.0, 7.0, &Vector3::z());
        assert!((end - target).norm() < 1e-9);
        assert!(((mid - root).norm() - 8.0).abs() < 1e-9);
        assert!(((end - mid).norm() - 7.0).abs() < 1e-9);
        assert!(mid.z > 0.0, "bends towards the pole");
    }

    #[test]
    fn two_bone_clamps_without_nan() {
        let root = Point3::origin();
        for target in [Point3::new(100.0, 0.0, 0.0), Point3::new(0.1, 0.0, 0.0), root] {
            let (mid, end) = two_bone(&root, &target, 8.0, 5.0, &Vector3::x());
            assert!(mid.coords.iter().chain(end.coords.iter()).all(|v| v.is_finite()));
            assert!(((mid - root).norm() - 8.0).abs() < 1e-6);
            assert!(((end - mid).norm() - 5.0).abs() < 1e-6);
        }
    }

    #[test]
    fn hind_limb_keeps_the_ankle_angle() {
        let hip = Point3::new(0.0, 0.0, 18.0);
        let paw = Point3::new(2.0, 0.0, 1.0);
        let lengths = [15.0, 17.0, 11.0];
        let (knee, ankle) = hind_limb(&hip, &paw, lengths, 90f64.to_radians(), &Vector3::x(), &Vector3::z());
        let a = (knee - ankle)
            .normalize()
            .dot(&(paw - ankle).normalize())
            .acos()
            .to_degrees();
        assert!((a - 90.0).abs() < 8.0, "ankle angle {a}");
        assert!(((knee - hip).norm() - 15.0).abs() < 1e-6);
        assert!(((ankle - paw).norm() - 11.0).abs() < 1e-6);
    }
}
