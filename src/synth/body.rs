//! The mouse's skin: ellipsoids and capsules hung on the posed skeleton, each surface point
//! carrying one of the six part labels and a material for the bottom camera's shading.
//!
//! Seen from above it reads as a mouse: a pointed head with two round ears, a pear-shaped
//! trunk widest at the hips, a thin tapering tail; the legs are thin capsules folded under the
//! trunk, so from the top little more than the paws' tips shows.

use super::mouse::{MouseInstance, TAIL_POINTS};
use crate::core::kinematics::PAW_SOLE_MM;
use crate::core::skeleton::{Joint, LIMBS, Part, Side};
use nalgebra::{Point3, Rotation3, Vector3};

/// A solid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shape {
    /// Centre, orientation (columns are the ellipsoid's axes) and semi-axes.
    Ellipsoid {
        centre: Point3<f64>,
        axes: Rotation3<f64>,
        radii: Vector3<f64>,
    },
    /// The points within `radius` of the segment `a`-`b`.
    Capsule {
        a: Point3<f64>,
        b: Point3<f64>,
        radius: f64,
    },
}

/// What a surface looks like to the bottom colour camera.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Material {
    Fur,
    Skin,
    Paw,
}

/// How a primitive's surface points are labelled.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Labeller {
    Fixed(Part),
    /// Trunk: front or rear by the side of the plane through `mid` (the mid-back joint) with
    /// normal `forward`, left or right by the side of the primitive's own sagittal plane
    /// (through `centre`, normal `left`).
    Trunk {
        mid: Point3<f64>,
        forward: Vector3<f64>,
        centre: Point3<f64>,
        left: Vector3<f64>,
    },
    /// The neck: head ahead of the plane through `origin` with normal `forward`, trunk behind.
    Neck {
        origin: Point3<f64>,
        forward: Vector3<f64>,
        left: Vector3<f64>,
    },
}

impl Labeller {
    /// The part label of the surface point `p` (same frame as the labeller).
    pub fn label(&self, p: &Point3<f64>) -> Part {
        match *self {
            Labeller::Fixed(part) => part,
            Labeller::Trunk {
                mid,
                forward,
                centre,
                left,
            } => Part::trunk((p - mid).dot(&forward) > 0.0, side_of(p, &centre, &left)),
            Labeller::Neck { origin, forward, left } => {
                if (p - origin).dot(&forward) > 0.0 {
                    Part::Head
                } else {
                    Part::trunk(true, side_of(p, &origin, &left))
                }
            }
        }
    }

    /// The same labeller with its points and directions mapped by `iso`.
    pub fn transformed(&self, iso: &nalgebra::Isometry3<f64>) -> Labeller {
        match *self {
            Labeller::Fixed(part) => Labeller::Fixed(part),
            Labeller::Trunk {
                mid,
                forward,
                centre,
                left,
            } => Labeller::Trunk {
                mid: iso * mid,
                forward: iso * forward,
                centre: iso * centre,
                left: iso * left,
            },
            Labeller::Neck { origin, forward, left } => Labeller::Neck {
                origin: iso * origin,
                forward: iso * forward,
                left: iso * left,
            },
        }
    }
}

fn side_of(p: &Point3<f64>, origin: &Point3<f64>, left: &Vector3<f64>) -> Side {
    if (p - origin).dot(left) >= 0.0 {
        Side::Left
    } else {
        Side::Right
    }
}

/// One piece of skin.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Primitive {
    pub shape: Shape,
    pub labeller: Labeller,
    pub material: Material,
}

/// Which leg a paw primitive belongs to, for the bottom view's ground truth.
pub const PAW_PRIMITIVES: usize = 4;

/// The skin of a posed mouse, in the world frame. The first [`PAW_PRIMITIVES`] primitives are
/// the paws in [`Joint::PAWS`] order.
pub fn skin(m: &MouseInstance) -> Vec<Primitive> {
    let mut out = Vec::with_capacity(40);
    paw_skin(m, &mut out);
    leg_skin(m, &mut out);
    head_skin(m, &mut out);
    trunk_skin(m, &mut out);
    tail_skin(m, &mut out);
    out
}

fn ellipsoid(centre: Point3<f64>, axes: Rotation3<f64>, radii: [f64; 3]) -> Shape {
    Shape::Ellipsoid {
        centre,
        axes,
        radii: Vector3::new(radii[0], radii[1], radii[2]),
    }
}

/// The paws, first in the skin (their order is the paw boxes' order).
fn paw_skin(m: &MouseInstance, out: &mut Vec<Primitive>) {
    let s = m.scale;
    for paw in Joint::PAWS {
        let limb = LIMBS.iter().find(|l| l.paw == paw).copied().unwrap_or(LIMBS[0]);
        let heading = super::mouse::flat_heading(m.frame(limb.root));
        let (len, width) = if limb.fore { (3.2, 2.4) } else { (4.8, 2.6) };
        let axes = Rotation3::from_axis_angle(&Vector3::z_axis(), heading.y.atan2(heading.x));
        out.push(Primitive {
            shape: ellipsoid(m.joint(paw), axes, [len * s, width * s, PAW_SOLE_MM * s]),
            labeller: Labeller::Fixed(Part::trunk(limb.fore, limb.side)),
            material: Material::Paw,
        });
    }
}

/// Legs, folded under the trunk.
fn leg_skin(m: &MouseInstance, out: &mut Vec<Primitive>) {
    let s = m.scale;
    for limb in LIMBS {
        let root = if limb.fore {
            m.shoulders[usize::from(limb.side == Side::Right)]
        } else {
            m.joint(limb.root)
        };
        let part = Part::trunk(limb.fore, limb.side);
        let radii = if limb.fore { [2.6, 1.8, 1.3] } else { [3.6, 2.2, 1.5] };
        let points = [root, m.joint(limb.upper), m.joint(limb.lower), m.joint(limb.paw)];
        for (k, r) in radii.into_iter().enumerate() {
            out.push(Primitive {
                shape: Shape::Capsule {
                    a: points[k],
                    b: points[k + 1],
                    radius: r * s,
                },
                labeller: Labeller::Fixed(part),
                material: if k == 2 { Material::Skin } else { Material::Fur },
            });
        }
    }
}

/// Head: cranium and muzzle, ears.
fn head_skin(m: &MouseInstance, out: &mut Vec<Primitive>) {
    let s = m.scale;
    let g = m.girth;
    let t = m.stature;
    let head = m.joint(Joint::Head);
    let snout = m.joint(Joint::Snout);
    let head_frame = *m.frame(Joint::Head);
    let muzzle_len = (snout - head).norm();
    out.push(Primitive {
        shape: ellipsoid(
            head - head_frame * Vector3::new(1.0 * s, 0.0, 0.0),
            head_frame,
            [8.5 * s, 7.8 * s * g, 6.0 * s * t],
        ),
        labeller: Labeller::Fixed(Part::Head),
        material: Material::Fur,
    });
    out.push(Primitive {
        shape: ellipsoid(
            head + (snout - head) * 0.5 - head_frame * Vector3::new(0.0, 0.0, 0.6 * s),
            head_frame,
            [0.5 * muzzle_len + 1.6 * s, 4.6 * s * g, 4.0 * s * t],
        ),
        labeller: Labeller::Fixed(Part::Head),
        material: Material::Fur,
    });
    for (ear, side) in [(Joint::LeftEar, Side::Left), (Joint::RightEar, Side::Right)] {
        // A thin disc facing outward and a little forward, laid back along the head as a
        // walking mouse carries its ears.
        let turn = Rotation3::from_axis_angle(&Vector3::z_axis(), side.sign() * 1.0);
        let tilt = Rotation3::from_axis_angle(&Vector3::y_axis(), -0.8);
        out.push(Primitive {
            shape: ellipsoid(m.joint(ear), head_frame * turn * tilt, [1.2 * s, 4.0 * s, 4.0 * s]),
            labeller: Labeller::Fixed(Part::Head),
            material: Material::Skin,
        });
    }
}

/// Trunk: overlapping ellipsoids along the spine from the tail base to the neck, their
/// width and height following a mouse's profile (widest over the hips, narrowing to the
/// neck), so the outline from above is smooth. Centres sit a little below the spine, which
/// runs along the back.
fn trunk_skin(m: &MouseInstance, out: &mut Vec<Primitive>) {
    let s = m.scale;
    let g = m.girth;
    let t = m.stature;
    let spine = [
        Joint::TailBase,
        Joint::Rump,
        Joint::MidBack,
        Joint::Withers,
        Joint::Neck,
    ];
    let lengths: Vec<f64> = spine
        .windows(2)
        .map(|w| (m.joint(w[1]) - m.joint(w[0])).norm())
        .collect();
    let total: f64 = lengths.iter().sum();
    let mid_back = m.joint(Joint::MidBack);
    let front_normal = m.frame(Joint::Withers) * Vector3::x();
    const SAMPLES: usize = 10;
    for k in 0..SAMPLES {
        let u = 0.04 + 0.96 * k as f64 / (SAMPLES - 1) as f64;
        let (centre_on_spine, frame) = along(&spine, &lengths, total * u, m);
        let [ry, rz] = trunk_profile(u);
        let centre = centre_on_spine - frame * Vector3::new(0.0, 0.0, 1.8 * s * t);
        let step = total / (SAMPLES - 1) as f64;
        out.push(Primitive {
            shape: ellipsoid(centre, frame, [1.2 * step.max(6.0 * s), ry * s * g, rz * s * t]),
            labeller: Labeller::Trunk {
                mid: mid_back,
                forward: front_normal,
                left: frame * Vector3::y(),
                centre,
            },
            material: Material::Fur,
        });
    }
    let neck_frame = *m.frame(Joint::Neck);
    out.push(Primitive {
        shape: ellipsoid(
            m.joint(Joint::Neck) - neck_frame * Vector3::new(-s, 0.0, 1.6 * s),
            neck_frame,
            [7.5 * s, 8.0 * s * g, 7.0 * s],
        ),
        labeller: Labeller::Neck {
            origin: m.joint(Joint::Neck),
            forward: neck_frame * Vector3::x(),
            left: neck_frame * Vector3::y(),
        },
        material: Material::Fur,
    });
}

/// Tail: tapering capsules along its centre line.
fn tail_skin(m: &MouseInstance, out: &mut Vec<Primitive>) {
    let s = m.scale;
    for k in 0..TAIL_POINTS - 1 {
        let t = k as f64 / (TAIL_POINTS - 2) as f64;
        out.push(Primitive {
            shape: Shape::Capsule {
                a: m.tail[k],
                b: m.tail[k + 1],
                radius: (2.4 - 1.6 * t) * s,
            },
            labeller: Labeller::Fixed(Part::Tail),
            material: Material::Skin,
        });
    }
}

/// The point at arc length `at` along the spine polyline `spine` (segment lengths `lengths`)
/// and the frame of the segment it falls in (x along the segment).
fn along(spine: &[Joint], lengths: &[f64], at: f64, m: &MouseInstance) -> (Point3<f64>, Rotation3<f64>) {
    let mut left = at;
    for (k, &len) in lengths.iter().enumerate() {
        if left <= len || k + 1 == lengths.len() {
            let (a, b) = (m.joint(spine[k]), m.joint(spine[k + 1]));
            let t = if len > 1e-9 { (left / len).clamp(0.0, 1.0) } else { 0.0 };
            // The segment's frame is stored at its anterior joint (the rump's for the pelvis).
            let frame = if spine[k] == Joint::TailBase {
                *m.frame(Joint::Rump)
            } else {
                *m.frame(spine[k + 1])
            };
            return (a + (b - a) * t, frame);
        }
        left -= len;
    }
    (m.joint(spine[0]), *m.frame(Joint::Rump))
}

/// Half-width and half-height (mm, unscaled) of the trunk at fraction `u` of the way from the
/// tail base to the neck.
fn trunk_profile(u: f64) -> [f64; 2] {
    const PROFILE: [(f64, f64, f64); 7] = [
        (0.0, 6.0, 5.5),
        (0.12, 11.0, 9.5),
        (0.28, 14.0, 12.5),
        (0.45, 14.2, 12.8),
        (0.62, 13.0, 11.5),
        (0.8, 11.0, 9.8),
        (1.0, 8.8, 8.0),
    ];
    for w in PROFILE.windows(2) {
        let ((u0, y0, z0), (u1, y1, z1)) = (w[0], w[1]);
        if u <= u1 {
            let t = ((u - u0) / (u1 - u0)).clamp(0.0, 1.0);
            return [y0 + (y1 - y0) * t, z0 + (z1 - z0) * t];
        }
    }
    [PROFILE[6].1, PROFILE[6].2]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::geometry::Rig;
    use crate::core::noise::DepthNoise;
    use crate::synth::mouse::{Behaviour, Placement, behaviour_params, pose_mouse};
    use crate::synth::render::Cage;
    use crate::synth::views::render_top;
    use nalgebra::Point2;
    use rand::SeedableRng;

    /// The body seen from above, tail left out: per 5 mm slice along the mouse (from its tail
    /// base forward, mouse frame), its width and the highest point (mm above the floor).
    fn top_profile(m: &MouseInstance) -> Vec<(f64, f64, f64)> {
        let rig = Rig::default_rig();
        let cam = &rig.depth;
        let view = render_top(
            cam,
            &Cage::new(cam),
            &skin(m),
            None,
            2,
            &DepthNoise::default(),
            &mut rand_chacha::ChaCha8Rng::seed_from_u64(1),
        );
        let base = m.joint(Joint::TailBase);
        let r = view.region;
        let mut slices = vec![(f64::INFINITY, f64::NEG_INFINITY, 0.0f64); 40];
        for (k, (&d, &label)) in view.depth.iter().zip(&view.label).enumerate() {
            if label == 255 || label == Part::Tail.label() || d == 0 {
                continue;
            }
            let px = Point2::new(
                f64::from(r.x0) + (k % r.width as usize) as f64,
                f64::from(r.y0) + (k / r.width as usize) as f64,
            );
            let p = cam.world_from_camera * cam.intrinsics.unproject(&px, f64::from(d));
            let (x, y) = (p.x - base.x, p.y - base.y);
            if let Ok(slice) = usize::try_from((x / 5.0).floor() as i64) {
                if let Some(s) = slices.get_mut(slice) {
                    *s = (s.0.min(y), s.1.max(y), s.2.max(p.z));
                }
            }
        }
        slices
            .into_iter()
            .enumerate()
            .filter(|(_, s)| s.1 > s.0)
            .map(|(k, s)| (5.0 * k as f64 + 2.5, s.1 - s.0, s.2))
            .collect()
    }

    /// The shape figures of docs/MOUSE-SHAPE.md, on the unscaled mouse: seen from above, its
    /// highest and widest parts lie behind the body's middle, the head end (front fifth) is
    /// lower and narrower, the back 25-35 mm high and the body at most about 30 mm wide (adult
    /// C57BL/6 mice), for standing, walking, sniffing and a hunched back; rearing keeps its
    /// widest part behind the middle.
    #[test]
    fn seen_from_above_the_mouse_is_widest_and_highest_behind_its_middle() {
        let hunched = |mut p: crate::synth::mouse::PoseParams| {
            crate::synth::Carriage {
                hunch: 0.3,
                ..crate::synth::Carriage::default()
            }
            .apply(&mut p);
            p
        };
        let cases = [
            ("stand", behaviour_params(Behaviour::Stand, 0.25, 0.0, 0.0, 0.0, 0.5)),
            ("walk", behaviour_params(Behaviour::Walk, 0.25, 0.0, 0.0, 0.0, 0.5)),
            (
                "walk, head up",
                behaviour_params(Behaviour::Walk, 0.6, 0.0, 0.0, 0.8, 0.8),
            ),
            ("sniff", behaviour_params(Behaviour::Sniff, 0.25, 0.0, 0.0, 0.0, 0.9)),
            (
                "hunched",
                hunched(behaviour_params(Behaviour::Stand, 0.0, 0.0, 0.0, 0.0, 0.5)),
            ),
            ("rear", behaviour_params(Behaviour::Rear, 0.25, 0.0, 0.0, 0.0, 0.5)),
        ];
        for (name, params) in cases {
            let m = pose_mouse(&params, &Placement::default());
            let profile = top_profile(&m);
            let length = profile.last().map_or(0.0, |s| s.0 + 2.5);
            let rear = |x: f64| x < 0.5 * length;
            let widest = profile
                .iter()
                .copied()
                .fold((0.0, 0.0, 0.0), |a, s| if s.1 > a.1 { s } else { a });
            assert!(
                rear(widest.0),
                "{name}: widest at {widest:?} of {length} mm: {profile:?}"
            );
            if name == "rear" {
                continue;
            }
            let highest = profile
                .iter()
                .copied()
                .fold((0.0, 0.0, 0.0), |a, s| if s.2 > a.2 { s } else { a });
            assert!(
                rear(highest.0),
                "{name}: highest at {highest:?} of {length} mm: {profile:?}"
            );
            assert!((25.0..=35.0).contains(&highest.2), "{name}: back {highest:?}");
            assert!((25.0..=32.0).contains(&widest.1), "{name}: width {widest:?}");
            let head: Vec<_> = profile.iter().filter(|s| s.0 > 0.8 * length).collect();
            let head_height = head.iter().map(|s| s.2).fold(0.0, f64::max);
            let head_width = head.iter().map(|s| s.1).fold(0.0, f64::max);
            let lower_by = if name == "walk, head up" { 1.0 } else { 4.0 };
            assert!(
                head_height <= highest.2 - lower_by,
                "{name}: head {head_height} mm high: {profile:?}"
            );
            assert!(
                head_width <= widest.1 - 5.0,
                "{name}: head {head_width} mm wide: {profile:?}"
            );
        }
    }
}
