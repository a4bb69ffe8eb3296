//! Step 3 of the paper: the body's joints from the top view, the paws found in the bottom view,
//! and the limbs between them (joints 1-12, 21-24 and 13-20 of `core::skeleton`).
//!
//! Each detected paw is the ray from the bottom camera through the detection's centre, met
//! with the plane a resting paw's joint lies in (its sole's radius above the glass). Paws are
//! given to the four legs by where they lie along and across the body's axis, each leg
//! preferring the place its paw had in the last frames, so the assignment holds from frame to
//! frame. Fore limbs follow by two-bone inverse kinematics from the shoulder, hind limbs with
//! the knee-ankle-paw angle at 90 degrees; a paw no camera sees takes its neutral stance.
//!
//! Everything here is pure: [`Fuser::fuse`] is called once per frame, in frame order.

use crate::core::geometry::Camera;
use crate::core::kinematics::PAW_SOLE_MM;
use crate::core::kinematics::{chest_paw, face_paw, fore_limb, hind_limb, stance_paw};
use crate::core::pose::{JointEstimate, JointSource, Pose};
use crate::core::skeleton::{BoneLengths, Joint, LIMBS, LimbChain};
use crate::vision::paws::PawDetection;
use nalgebra::{Point2, Point3, Rotation3, Vector3};

/// The knee-ankle-paw angle of the hind limbs (the paper's Fig. "limb").
pub const ANKLE_ANGLE_DEG: f64 = 90.0;

/// A trunk raised more than this (radians, rump to withers) rears or grooms: the fore paws
/// leave the glass. Walking, running and sniffing mice stay under 0.2, rearing and grooming
/// ones over 0.47 (in the synthesis engine's pose library).
pub const RAISED_TRUNK_RAD: f64 = 0.35;

/// Where between the chest (0) and the face (1) a raised fore paw is put when no camera sees
/// it: the top view's joints do not tell rearing (paws towards the chest) from grooming (paws
/// at the face). Over the pose library's rearing and grooming poses, with exact body joints,
/// this puts the fore paws 8.4 mm from the truth on average (8.6 mm at the chest, 13.0 mm at
/// the face, 35 mm in the standing stance).
pub const RAISED_PAW_TOWARDS_FACE: f64 = 0.25;

/// How much further than its bones' summed length a leg is taken to reach (the estimated
/// body joints and bone lengths are not exact).
const REACH_SLACK: f64 = 1.1;

/// A paw lies at least this far (mm, for a mouse of scale 1) to its own side of the spine
/// seen from above: a standing mouse's paws lie 9-11 mm out, a grooming mouse's fore paws
/// about 4 mm out at its face; the snout, the chin, the belly, the genitals and the tail base,
/// which a paw detector takes for paws on real bottom views, lie on the spine.
pub const MIN_OFF_SPINE_MM: f64 = 3.0;

/// Tuning of the fusion.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FusionConfig {
    /// A paw further than this (mm, for a mouse of scale 1) from where its leg can put it is
    /// not that leg's.
    pub gate_mm: f64,
    /// For how many depth frames a leg remembers where its paw was.
    pub memory_frames: u64,
    /// How many detections (the surest) are considered per frame.
    pub max_detections: usize,
    /// Score of a joint in its default configuration.
    pub default_score: f64,
}

impl Default for FusionConfig {
    fn default() -> Self {
        Self {
            gate_mm: 24.0,
            memory_frames: 6,
            max_detections: 8,
            default_score: 0.05,
        }
    }
}

/// The body's frame and size, estimated from joints 1-12.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BodyAxes {
    /// Horizontal forward direction at the withers (fore limbs) and at the rump (hind limbs).
    pub fore_forward: Vector3<f64>,
    pub hind_forward: Vector3<f64>,
    /// The fore limbs' roots, left then right.
    pub shoulders: [Point3<f64>; 2],
    /// The mouse's size factor (its spine length over the default's).
    pub scale: f64,
    /// How far the trunk rises from the rump to the withers, radians.
    pub trunk_pitch: f64,
    /// The withers' frame (x along the spine, y left, z dorsal) and the head's (x from head to
    /// snout).
    pub withers_frame: Rotation3<f64>,
    pub head_frame: Rotation3<f64>,
    pub snout: Point3<f64>,
    /// The bone lengths at that scale.
    pub bones: BoneLengths,
    /// The spine seen from above, snout to tail base (world x, y).
    pub spine: [Point2<f64>; 7],
}

impl BodyAxes {
    /// The axes of a pose whose joints 1-12 are estimated; `None` when one is missing.
    pub fn of(pose: &Pose) -> Option<Self> {
        let p = |j: Joint| {
            let e = pose.joint(j);
            (e.source != JointSource::Missing).then_some(e.position_mm)
        };
        // The spine from snout to tail base: the joint table's first seven.
        let spine = &Joint::ALL[..=Joint::TailBase.index()];
        let mut length = 0.0;
        for w in spine.windows(2) {
            length += (p(w[0])? - p(w[1])?).norm();
        }
        let mut seen_from_above = [Point2::origin(); 7];
        for (q, j) in seen_from_above.iter_mut().zip(spine) {
            let at = p(*j)?;
            *q = Point2::new(at.x, at.y);
        }
        let scale = (length / BoneLengths::default().body_length()).clamp(0.8, 1.25);
        let bones = BoneLengths::default().scaled(scale);
        let (withers, mid_back, rump) = (p(Joint::Withers)?, p(Joint::MidBack)?, p(Joint::Rump)?);
        let fore_forward = horizontal(withers - mid_back).or_else(|| horizontal(p(Joint::Snout)? - rump))?;
        let hind_forward = horizontal(mid_back - rump).unwrap_or(fore_forward);
        // The withers' frame: along the spine segment, left horizontal, and up from both.
        let x = (withers - mid_back).try_normalize(1e-9).unwrap_or(fore_forward);
        let withers_frame = frame(x, fore_forward);
        let shoulders = [1.0, -1.0].map(|sign| {
            withers
                + withers_frame * Vector3::new(bones.shoulder_forward, sign * bones.shoulder_side, -bones.shoulder_down)
        });
        let (snout, head) = (p(Joint::Snout)?, p(Joint::Head)?);
        let muzzle = (snout - head).try_normalize(1e-9).unwrap_or(x);
        let rise = withers - rump;
        Some(Self {
            fore_forward,
            hind_forward,
            shoulders,
            scale,
            bones,
            trunk_pitch: rise.z.atan2(Vector3::new(rise.x, rise.y, 0.0).norm()),
            withers_frame,
            head_frame: frame(muzzle, horizontal(muzzle).unwrap_or(fore_forward)),
            snout,
            spine: seen_from_above,
        })
    }

    /// How far `p` lies to the left of the spine seen from above (mm; negative to the
    /// right): its distance to the nearest point of the spine's segments, signed by the side
    /// of that segment it lies on.
    pub fn off_spine(&self, p: &Point3<f64>) -> f64 {
        let q = Point2::new(p.x, p.y);
        let mut best = (f64::INFINITY, 0.0);
        for w in self.spine.windows(2) {
            // From the rear point to the front one: left of it is the mouse's left.
            let (front, rear) = (w[0], w[1]);
            let d = front - rear;
            let t = ((q - rear).dot(&d) / d.norm_squared().max(1e-12)).clamp(0.0, 1.0);
            let off = q - (rear + d * t);
            let distance = off.norm();
            if distance < best.0 {
                let cross = d.x * off.y - d.y * off.x;
                best = (distance, if cross < 0.0 { -distance } else { distance });
            }
        }
        best.1
    }

    /// Where a paw no camera sees is put: its stance on the glass, or for the fore paws of a
    /// mouse that rears or grooms, in front of its chest towards its face.
    pub fn default_paw(&self, limb: &LimbChain, pose: &Pose) -> Point3<f64> {
        let root = self.root(limb, pose);
        let sign = limb.side.sign();
        if limb.fore && self.trunk_pitch > RAISED_TRUNK_RAD {
            let chest = chest_paw(&root, &self.withers_frame, sign, self.scale);
            let face = face_paw(&self.snout, &self.head_frame, sign, self.scale);
            let paw = chest + (face - chest) * RAISED_PAW_TOWARDS_FACE;
            return Point3::new(paw.x, paw.y, paw.z.max(PAW_SOLE_MM * self.scale));
        }
        stance_paw(&root, &self.forward(limb), sign, limb.fore, self.scale, PAW_SOLE_MM)
    }

    /// Where a limb hangs from: its shoulder or its hip joint.
    fn root(&self, limb: &LimbChain, pose: &Pose) -> Point3<f64> {
        if limb.fore {
            self.shoulders[usize::from(limb.side.sign() < 0.0)]
        } else {
            pose.joint(limb.root).position_mm
        }
    }

    fn forward(&self, limb: &LimbChain) -> Vector3<f64> {
        if limb.fore {
            self.fore_forward
        } else {
            self.hind_forward
        }
    }
}

/// The right-handed frame with x along `x` and y to the left of the horizontal `forward`.
fn frame(x: Vector3<f64>, forward: Vector3<f64>) -> Rotation3<f64> {
    let left = Vector3::z().cross(&forward);
    let up = x.cross(&left).try_normalize(1e-9).unwrap_or_else(Vector3::z);
    let left = up.cross(&x);
    Rotation3::from_basis_unchecked(&[x, left, up])
}

fn horizontal(v: Vector3<f64>) -> Option<Vector3<f64>> {
    Vector3::new(v.x, v.y, 0.0).try_normalize(1e-6)
}

/// Where the ray through `pixel` of `camera` meets the horizontal plane at height `z_mm`;
/// `None` when it runs parallel to the plane or away from it.
pub fn on_plane(camera: &Camera, pixel: &Point2<f64>, z_mm: f64) -> Option<Point3<f64>> {
    let origin = camera.centre();
    let direction = camera.world_from_camera.rotation * camera.intrinsics.ray(pixel);
    if direction.z.abs() < 1e-9 {
        return None;
    }
    let t = (z_mm - origin.z) / direction.z;
    (t > 0.0).then(|| origin + direction * t)
}

/// A paw seen by the bottom camera: where its ray meets the glass (world frame), and the ray's
/// direction from the camera.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Seen {
    position: Point3<f64>,
    direction: Vector3<f64>,
    score: f64,
}

impl Seen {
    /// Where the paw is for a leg hanging from `root` with reach `reach`: on the glass when
    /// the leg reaches it there; otherwise the paw is lifted (a rearing mouse's fore paws) and
    /// it is the point of its ray nearest to where the leg holds a lifted paw (`lifted`).
    fn place(&self, root: &Point3<f64>, reach: f64, lifted: &Point3<f64>, sole: f64) -> Point3<f64> {
        if (self.position - root).norm() <= reach {
            return self.position;
        }
        let d = self.direction.normalize();
        let along = (lifted - self.position).dot(&d);
        let p = self.position + d * along;
        if p.z < sole { self.position } else { p }
    }
}

/// Fuses the views of one rig, frame after frame.
#[derive(Clone, Debug)]
pub struct Fuser {
    color: Camera,
    config: FusionConfig,
    /// Per leg (in [`LIMBS`] order): the depth frame and place its paw was last seen.
    last: [Option<(u64, Point3<f64>)>; 4],
    seen: Vec<Seen>,
}

impl Fuser {
    /// A fuser for the rig's bottom camera `color`.
    pub fn new(color: Camera, config: FusionConfig) -> Self {
        Self {
            color,
            config,
            last: [None; 4],
            seen: Vec::new(),
        }
    }

    /// A fuser for the same rig that has seen nothing yet (another mouse's).
    pub fn fresh(&self) -> Self {
        Self::new(self.color, self.config)
    }

    /// Completes `pose` (whose joints 1-12 come from the depth image) with the paws in
    /// `paws` (detections in the bottom frame of depth frame `seq`, or none when there was no
    /// colour frame) and the limbs. A pose without its body joints is left as it is.
    pub fn fuse(&mut self, seq: u64, pose: &mut Pose, paws: &[PawDetection]) {
        let Some(axes) = BodyAxes::of(pose) else {
            return;
        };
        let sole = PAW_SOLE_MM * axes.scale;
        self.seen.clear();
        self.seen.extend(paws.iter().filter_map(|d| {
            let (x, y) = d.centre();
            on_plane(&self.color, &Point2::new(x, y), sole).map(|position| Seen {
                position,
                direction: position - self.color.centre(),
                // Detector scores grow without bound (grouped windows); joints' are in [0, 1).
                score: f64::from(d.score.max(0.0)) / (1.0 + f64::from(d.score.max(0.0))),
            })
        }));
        self.seen.sort_by(|a, b| b.score.total_cmp(&a.score));
        self.seen.truncate(self.config.max_detections);

        // The limbs hang from the body: no surer than its least sure joint (a joint not
        // reported, such as a tail tip no camera saw, does not count).
        let body_score = Joint::MAIN_BODY
            .iter()
            .map(|j| pose.joint(*j))
            .filter(|e| e.source != JointSource::Missing)
            .map(|e| e.score)
            .fold(f64::INFINITY, f64::min)
            .clamp(0.0, 1.0);
        let assigned = self.assign(seq, pose, &axes);
        for (k, limb) in LIMBS.iter().enumerate() {
            let root = axes.root(limb, pose);
            let forward = axes.forward(limb);
            let lengths = axes.bones.limb(limb.fore);
            let (paw, source, score) = match assigned[k] {
                Some(i) => {
                    let s = self.seen[i];
                    self.last[k] = Some((seq, s.position));
                    let reach = lengths.iter().sum::<f64>() * REACH_SLACK;
                    let paw = s.place(&root, reach, &axes.default_paw(limb, pose), sole);
                    (paw, JointSource::Paw, s.score)
                }
                None => (
                    axes.default_paw(limb, pose),
                    JointSource::Default,
                    self.config.default_score,
                ),
            };
            let (upper, lower) = if limb.fore {
                fore_limb(&root, &paw, lengths, &forward, &Vector3::z())
            } else {
                hind_limb(
                    &root,
                    &paw,
                    lengths,
                    ANKLE_ANGLE_DEG.to_radians(),
                    &forward,
                    &Vector3::z(),
                )
            };
            let (limb_source, limb_score) = match source {
                JointSource::Paw => (JointSource::Ik, score.min(body_score)),
                other => (other, score),
            };
            let mut set = |j: Joint, position_mm, source, score| {
                *pose.joint_mut(j) = JointEstimate {
                    position_mm,
                    score,
                    source,
                };
            };
            set(limb.paw, paw, source, score);
            set(limb.upper, upper, limb_source, limb_score);
            set(limb.lower, lower, limb_source, limb_score);
        }
    }

    /// The detection each leg gets (an index into `self.seen`), minimising the summed distance
    /// of each paw to where its leg would put it; a leg may get none.
    fn assign(&self, seq: u64, pose: &Pose, axes: &BodyAxes) -> [Option<usize>; 4] {
        let gate = self.config.gate_mm * axes.scale;
        let n = self.seen.len();
        // cost[leg][detection]: infinite where the detection cannot be that leg's.
        let mut cost = [[f64::INFINITY; 8]; 4];
        for (k, limb) in LIMBS.iter().enumerate() {
            let root = axes.root(limb, pose);
            let forward = axes.forward(limb);
            let stance = stance_paw(&root, &forward, limb.side.sign(), limb.fore, axes.scale, PAW_SOLE_MM);
            let remembered = self.last[k]
                .filter(|(at, _)| seq.saturating_sub(*at) <= self.config.memory_frames && *at <= seq)
                .map(|(_, p)| p);
            // Which side of the body a paw is on, measured from the middle of the limb pair.
            let pair_middle = if limb.fore {
                nalgebra::center(&axes.shoulders[0], &axes.shoulders[1])
            } else {
                nalgebra::center(
                    &pose.joint(Joint::LeftHip).position_mm,
                    &pose.joint(Joint::RightHip).position_mm,
                )
            };
            let left = Vector3::z().cross(&forward);
            let reach = axes.bones.limb(limb.fore).iter().sum::<f64>() * REACH_SLACK;
            let lifted = axes.default_paw(limb, pose);
            let sole = PAW_SOLE_MM * axes.scale;
            for (i, s) in self.seen.iter().enumerate().take(8) {
                let side = (s.position - pair_middle).dot(&left) * limb.side.sign();
                if side < -2.0 * axes.scale {
                    continue; // on the other side of the body
                }
                // A box no leg of this body can put a paw in is something else (the snout,
                // the tail base, a mark on the glass): out of the leg's reach, or on the spine.
                let placed = s.place(&root, reach, &lifted, sole);
                if (placed - root).norm() > reach
                    || axes.off_spine(&placed) * limb.side.sign() < MIN_OFF_SPINE_MM * axes.scale
                {
                    continue;
                }
                let flat = |p: &Point3<f64>| Vector3::new(s.position.x - p.x, s.position.y - p.y, 0.0).norm();
                let d = remembered.map_or(flat(&stance), |r| flat(&r).min(flat(&stance)));
                if d <= gate {
                    cost[k][i] = d;
                }
            }
        }
        let mut best = (f64::INFINITY, [None; 4]);
        let mut current = [None; 4];
        search(&cost, n.min(8), gate, 0, 0, 0.0, &mut current, &mut best);
        best.1
    }
}

/// Exhaustive search over the legs' choices (at most 9 x 8 x 7 x 6 of them); a leg without a
/// paw costs `gate`.
#[allow(clippy::too_many_arguments)]
fn search(
    cost: &[[f64; 8]; 4],
    n: usize,
    gate: f64,
    leg: usize,
    used: u16,
    total: f64,
    current: &mut [Option<usize>; 4],
    best: &mut (f64, [Option<usize>; 4]),
) {
    if total >= best.0 {
        return;
    }
    if leg == 4 {
        *best = (total, *current);
        return;
    }
    for i in 0..n {
        if used & (1 << i) == 0 && cost[leg][i].is_finite() {
            current[leg] = Some(i);
            search(
                cost,
                n,
                gate,
                leg + 1,
                used | (1 << i),
                total + cost[leg][i],
                current,
                best,
            );
        }
    }
    current[leg] = None;
    search(cost, n, gate, leg + 1, used, total + gate, current, best);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::geometry::Rig;
    use crate::synth::mouse::{Placement, PoseParams, pose_mouse};

    /// A detection box centred on `c` (colour image pixels).
    fn detection_at(c: Point2<f64>, score: f32) -> PawDetection {
        PawDetection {
            x0: c.x as f32 - 6.0,
            y0: c.y as f32 - 6.0,
            x1: c.x as f32 + 6.0,
            y1: c.y as f32 + 6.0,
            score,
        }
    }

    /// The pose of `m` as the body stage gives it: joints 1-12, exact.
    fn body_pose(m: &crate::synth::mouse::MouseInstance) -> Pose {
        let mut pose = Pose::default();
        for j in Joint::MAIN_BODY {
            *pose.joint_mut(j) = JointEstimate {
                position_mm: m.joint(j),
                score: 0.9,
                source: JointSource::Depth,
            };
        }
        pose
    }

    /// A posed mouse, its pose as the body stage gives it (joints 1-12 exact), and the
    /// detections a perfect paw detector would give for its paws on the glass.
    fn scene(placement: &Placement, rig: &Rig) -> (crate::synth::mouse::MouseInstance, Pose, Vec<PawDetection>) {
        let m = pose_mouse(&PoseParams::default(), placement);
        let pose = body_pose(&m);
        let detections = Joint::PAWS
            .iter()
            .filter_map(|j| rig.color.project_world(&m.joint(*j)))
            .map(|c| detection_at(c, 0.8))
            .collect();
        (m, pose, detections)
    }

    fn error(m: &crate::synth::mouse::MouseInstance, pose: &Pose, j: Joint) -> f64 {
        (pose.joint(j).position_mm - m.joint(j)).norm()
    }

    #[test]
    fn paws_go_to_their_legs_on_rotated_and_mirrored_mice() {
        let rig = Rig::default_rig();
        for heading in [0.0, 0.7, 2.0, -2.5, std::f64::consts::PI] {
            for mirrored in [false, true] {
                let placement = Placement {
                    x_mm: 40.0,
                    y_mm: -30.0,
                    heading,
                    ..Placement::default()
                };
                let (m, pose, mut detections) = scene(&placement, &rig);
                if mirrored {
                    // The same paws listed in another order: the assignment must not care.
                    detections.reverse();
                }
                assert_each_paw_found(&rig, &m, &pose, &detections, heading);
            }
        }
    }

    /// Fuses `detections` into `pose` in a fresh fuser and checks that each paw took its own
    /// box, within 1 mm of the truth `m`.
    fn assert_each_paw_found(
        rig: &Rig,
        m: &crate::synth::mouse::MouseInstance,
        pose: &Pose,
        detections: &[PawDetection],
        heading: f64,
    ) {
        let mut fuser = Fuser::new(rig.color, FusionConfig::default());
        let mut fused = pose.clone();
        fuser.fuse(0, &mut fused, detections);
        for j in Joint::PAWS {
            assert_eq!(fused.joint(j).source, JointSource::Paw, "{j:?} at heading {heading}");
            assert!(
                error(m, &fused, j) < 1.0,
                "{j:?} at heading {heading}: {}",
                error(m, &fused, j)
            );
        }
    }

    #[test]
    fn a_mirror_image_mouse_swaps_left_and_right() {
        // The mouse reflected across its own axis: the paws that were left are now right.
        let rig = Rig::default_rig();
        let (m, pose, _) = scene(&Placement::default(), &rig);
        let mirror = |p: Point3<f64>| Point3::new(p.x, -p.y, p.z);
        let mut mirrored = pose.clone();
        for j in Joint::MAIN_BODY {
            mirrored.joint_mut(j).position_mm = mirror(m.joint(j));
        }
        // Left and right hips trade places in the mirror.
        mirrored.joint_mut(Joint::LeftHip).position_mm = mirror(m.joint(Joint::RightHip));
        mirrored.joint_mut(Joint::RightHip).position_mm = mirror(m.joint(Joint::LeftHip));
        let detections: Vec<_> = Joint::PAWS
            .iter()
            .filter_map(|j| rig.color.project_world(&mirror(m.joint(*j))))
            .map(|c| detection_at(c, 0.8))
            .collect();
        let mut fuser = Fuser::new(rig.color, FusionConfig::default());
        fuser.fuse(0, &mut mirrored, &detections);
        let expect = [
            (Joint::LeftForePaw, Joint::RightForePaw),
            (Joint::RightForePaw, Joint::LeftForePaw),
            (Joint::LeftHindPaw, Joint::RightHindPaw),
            (Joint::RightHindPaw, Joint::LeftHindPaw),
        ];
        for (ours, theirs) in expect {
            let d = (mirrored.joint(ours).position_mm - mirror(m.joint(theirs))).norm();
            assert!(d < 1.0, "{ours:?} is {d} mm from the mirrored {theirs:?}");
        }
    }

    #[test]
    fn missing_paws_take_the_default_configuration() {
        let rig = Rig::default_rig();
        let (m, pose, detections) = scene(&Placement::default(), &rig);
        let mut fuser = Fuser::new(rig.color, FusionConfig::default());
        let mut fused = pose.clone();
        // Only the first detection (the left fore paw) is seen.
        fuser.fuse(0, &mut fused, &detections[..1]);
        assert_eq!(fused.joint(Joint::LeftForePaw).source, JointSource::Paw);
        assert_eq!(fused.joint(Joint::LeftElbow).source, JointSource::Ik);
        for j in [
            Joint::RightForePaw,
            Joint::LeftHindPaw,
            Joint::RightHindPaw,
            Joint::RightKnee,
        ] {
            let e = fused.joint(j);
            assert_eq!(e.source, JointSource::Default, "{j:?}");
            assert!(e.position_mm.coords.iter().all(|v| v.is_finite()));
        }
        // The default stance of a standing mouse is where its paws stand.
        for j in [Joint::RightForePaw, Joint::RightHindPaw] {
            assert!(error(&m, &fused, j) < 3.0, "{j:?}: {}", error(&m, &fused, j));
        }
        // Nothing seen at all: every limb joint is the default, none is missing.
        let mut blind = pose.clone();
        fuser.fuse(100, &mut blind, &[]);
        for limb in LIMBS {
            for j in [limb.upper, limb.lower, limb.paw] {
                assert_eq!(blind.joint(j).source, JointSource::Default, "{j:?}");
            }
        }
    }

    #[test]
    fn a_rearing_mouse_holds_its_unseen_fore_paws_up() {
        let rig = Rig::default_rig();
        let params =
            crate::synth::mouse::behaviour_params(crate::synth::mouse::Behaviour::Rear, 0.3, 0.0, 0.0, 0.0, 0.8);
        let m = pose_mouse(&params, &Placement::default());
        let mut pose = body_pose(&m);
        let mut fuser = Fuser::new(rig.color, FusionConfig::default());
        fuser.fuse(0, &mut pose, &[]);
        for j in [Joint::LeftForePaw, Joint::RightForePaw] {
            assert_eq!(pose.joint(j).source, JointSource::Default);
            assert!(pose.joint(j).position_mm.z > 15.0, "{j:?} left on the glass");
            assert!(error(&m, &pose, j) < 15.0, "{j:?}: {}", error(&m, &pose, j));
        }
    }

    #[test]
    fn limbs_follow_the_paws_with_the_skeletons_lengths() {
        let rig = Rig::default_rig();
        let (m, pose, detections) = scene(&Placement::default(), &rig);
        let mut fuser = Fuser::new(rig.color, FusionConfig::default());
        let mut fused = pose.clone();
        fuser.fuse(0, &mut fused, &detections);
        for limb in LIMBS {
            for j in [limb.upper, limb.lower] {
                assert_eq!(fused.joint(j).source, JointSource::Ik);
                assert!(error(&m, &fused, j) < 4.0, "{j:?}: {}", error(&m, &fused, j));
            }
        }
    }

    /// Issue 27, item 5: a paw detector on real bottom views also boxes the snout, the chin
    /// and the tail base. With the real paws hidden, no leg takes such a box; with them in
    /// view, each leg still takes its own paw.
    #[test]
    fn boxes_at_the_snout_or_the_tail_base_fit_no_leg() {
        let rig = Rig::default_rig();
        for heading in [0.0, 1.1, -2.4] {
            let placement = Placement {
                x_mm: -20.0,
                y_mm: 25.0,
                heading,
                ..Placement::default()
            };
            let (m, pose, paws) = scene(&placement, &rig);
            let on_glass = |j: Joint| {
                let p = m.joint(j);
                rig.color.project_world(&Point3::new(p.x, p.y, 0.0)).expect("in view")
            };
            let chin = {
                let (s, h) = (m.joint(Joint::Snout), m.joint(Joint::Head));
                rig.color
                    .project_world(&Point3::new((s.x + h.x) / 2.0, (s.y + h.y) / 2.0, 0.0))
                    .expect("in view")
            };
            let tail_root = {
                let (b, r) = (m.joint(Joint::TailBase), m.joint(Joint::Rump));
                rig.color
                    .project_world(&Point3::new((b.x * 2.0 + r.x) / 3.0, (b.y * 2.0 + r.y) / 3.0, 0.0))
                    .expect("in view")
            };
            let false_boxes: Vec<PawDetection> = [on_glass(Joint::Snout), chin, on_glass(Joint::TailBase), tail_root]
                .into_iter()
                .map(|c| detection_at(c, 5.0))
                .collect();
            let mut fuser = Fuser::new(rig.color, FusionConfig::default());
            let mut fused = pose.clone();
            fuser.fuse(0, &mut fused, &false_boxes);
            for j in Joint::PAWS {
                assert_eq!(
                    fused.joint(j).source,
                    JointSource::Default,
                    "{j:?} took a box on the spine at heading {heading}"
                );
            }
            // The real paws beside the false boxes, in a fresh fuser: each leg takes its own.
            let mut all = paws.clone();
            all.extend(false_boxes);
            assert_each_paw_found(&rig, &m, &pose, &all, heading);
        }
    }

    #[test]
    fn off_spine_is_signed_by_the_side() {
        let rig = Rig::default_rig();
        let (m, pose, _) = scene(&Placement::default(), &rig);
        let axes = BodyAxes::of(&pose).expect("a whole body");
        assert!(axes.off_spine(&m.joint(Joint::MidBack)).abs() < 1e-6);
        assert!(axes.off_spine(&m.joint(Joint::LeftHindPaw)) > MIN_OFF_SPINE_MM);
        assert!(axes.off_spine(&m.joint(Joint::RightForePaw)) < -MIN_OFF_SPINE_MM);
    }

    #[test]
    fn a_stray_detection_far_from_the_mouse_is_ignored() {
        let rig = Rig::default_rig();
        let (_, pose, mut detections) = scene(&Placement::default(), &rig);
        let far = rig
            .color
            .project_world(&Point3::new(150.0, 120.0, 1.5))
            .expect("in view");
        detections.push(detection_at(far, 5.0));
        let mut fuser = Fuser::new(rig.color, FusionConfig::default());
        let mut fused = pose.clone();
        fuser.fuse(0, &mut fused, &detections);
        for j in Joint::PAWS {
            let p = fused.joint(j).position_mm;
            assert!((p.x - 150.0).abs() > 50.0, "{j:?} took the stray detection");
        }
    }
}
