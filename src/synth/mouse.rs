//! The kinematic mouse: pose parameters, forward kinematics from them to the 24 joints, and
//! the procedural library of distinct poses the datasets draw from.
//!
//! A pose is built in the mouse's own frame (x forward, y left, z up, origin on the floor
//! under the rump) from a handful of continuous parameters, so behaviours can blend smoothly
//! in a session, and then placed in the cage by a [`Placement`].

use crate::core::kinematics::{PAW_SOLE_MM, chest_paw, face_paw, fore_limb, hind_limb, stance_paw};
use crate::core::pose::JointPositions;
use crate::core::skeleton::{BoneLengths, Joint, LIMBS, Side};
use nalgebra::{Isometry3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use std::f64::consts::{PI, TAU};

/// The behaviours the pose generator and the session animator know.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Behaviour {
    Stand,
    Walk,
    Run,
    Turn,
    Bend,
    Rear,
    Groom,
    Sniff,
}

impl Behaviour {
    pub const ALL: [Behaviour; 8] = [
        Behaviour::Stand,
        Behaviour::Walk,
        Behaviour::Run,
        Behaviour::Turn,
        Behaviour::Bend,
        Behaviour::Rear,
        Behaviour::Groom,
        Behaviour::Sniff,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Behaviour::Stand => "stand",
            Behaviour::Walk => "walk",
            Behaviour::Run => "run",
            Behaviour::Turn => "turn",
            Behaviour::Bend => "bend",
            Behaviour::Rear => "rear",
            Behaviour::Groom => "groom",
            Behaviour::Sniff => "sniff",
        }
    }

    /// Stable small code stored in data files.
    pub fn code(self) -> u8 {
        self as u8
    }
}

/// Number of spine segments ahead of the rump: rump-mid_back, mid_back-withers,
/// withers-neck, neck-head, head-snout.
pub const SPINE_SEGMENTS: usize = 5;

/// The continuous parameters of one pose, in the mouse's own frame. Angles in radians,
/// lengths in millimetres of the unscaled mouse.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseParams {
    pub behaviour: Behaviour,
    /// Height of the rump joint above the floor.
    pub rump_height: f64,
    /// How far the trunk leans up from horizontal (rearing lifts it towards 80 degrees).
    pub trunk_pitch: f64,
    /// Lateral bend at each spine segment, positive to the mouse's left.
    pub yaw: [f64; SPINE_SEGMENTS],
    /// Pitch change at each spine segment, positive up.
    pub pitch: [f64; SPINE_SEGMENTS],
    /// Roll of the whole body about its long axis, positive lifts the right side.
    pub roll: f64,
    /// Yaw of the tail at its base (relative to straight back) and its curvature over its
    /// length, both positive to the left.
    pub tail_yaw: f64,
    pub tail_curl: f64,
    /// How high the tail is held above the floor near its base (0 drags it).
    pub tail_lift: f64,
    /// Paw offsets from their neutral stance points (x forward, y outward, z up), in the
    /// order of [`LIMBS`]: left fore, right fore, left hind, right hind.
    pub paw_offsets: [[f64; 3]; 4],
    /// 0: fore paws on the floor; 1: held in front of the chest (rearing); blends between.
    pub fore_raise: f64,
    /// 0..1: fore paws brought to the snout (grooming), on top of `fore_raise`.
    pub fore_to_face: f64,
    /// The knee-ankle-paw angle of the hind limbs.
    pub ankle_angle: f64,
}

impl Default for PoseParams {
    fn default() -> Self {
        Self {
            behaviour: Behaviour::Stand,
            rump_height: 16.0,
            trunk_pitch: 0.10,
            yaw: [0.0; SPINE_SEGMENTS],
            pitch: [0.0, -0.10, -0.12, -0.10, -0.20],
            roll: 0.0,
            tail_yaw: 0.0,
            tail_curl: 0.0,
            tail_lift: 4.0,
            paw_offsets: [[0.0; 3]; 4],
            fore_raise: 0.0,
            fore_to_face: 0.0,
            ankle_angle: 90f64.to_radians(),
        }
    }
}

/// Where and how big the mouse is: its placement in the cage and its individual shape.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Placement {
    /// Position of the rump's floor point in the world (mm; z is ignored, the floor is 0).
    pub x_mm: f64,
    pub y_mm: f64,
    /// Heading: the direction the mouse faces, counter-clockwise from world +x.
    pub heading: f64,
    /// Small body tilts (the paper's random pitch and roll): added to the trunk's pitch and the
    /// body's roll, with the paws kept on the floor.
    pub pitch: f64,
    pub roll: f64,
    /// Overall size (0.85-1.15 in datasets).
    pub scale: f64,
    /// Bone lengths before scaling (the defaults varied by up to 10 % each).
    pub bones: BoneLengths,
    /// Body girth relative to the default (how plump the mouse is).
    pub girth: f64,
    /// How tall the body is relative to the default beyond its scale: the back's height above
    /// the floor and the trunk's and head's depth (1 for every mouse but `adapt`'s).
    #[serde(default = "unit")]
    pub stature: f64,
}

fn unit() -> f64 {
    1.0
}

impl Default for Placement {
    fn default() -> Self {
        Self {
            x_mm: 0.0,
            y_mm: 0.0,
            heading: 0.0,
            pitch: 0.0,
            roll: 0.0,
            scale: 1.0,
            bones: BoneLengths::default(),
            girth: 1.0,
            stature: 1.0,
        }
    }
}

/// Number of points on the tail's centre line.
pub const TAIL_POINTS: usize = 9;

/// A posed mouse in the world frame: everything the skin and the renderers need.
#[derive(Clone, Debug, PartialEq)]
pub struct MouseInstance {
    pub joints: JointPositions,
    /// Orientation (x forward, y left, z dorsal) of the spine segment ending at each joint,
    /// indexed by joint; limbs and the tail carry the frame of their body attachment.
    pub frames: [Rotation3<f64>; crate::core::skeleton::JOINT_COUNT],
    /// The tail's centre line from `tail_base` to `tail_tip`.
    pub tail: [Point3<f64>; TAIL_POINTS],
    /// Shoulder points (fore limb roots), left then right.
    pub shoulders: [Point3<f64>; 2],
    /// Size factor of the skin (the placement's scale).
    pub scale: f64,
    pub girth: f64,
    /// [`Placement::stature`].
    pub stature: f64,
    pub behaviour: Behaviour,
}

impl MouseInstance {
    pub fn joint(&self, joint: Joint) -> Point3<f64> {
        self.joints[joint.index()]
    }

    pub fn frame(&self, joint: Joint) -> &Rotation3<f64> {
        &self.frames[joint.index()]
    }
}

/// The horizontal forward direction of a body frame (world x when the frame points straight
/// up or down).
pub fn flat_heading(frame: &Rotation3<f64>) -> Vector3<f64> {
    let f = frame * Vector3::x();
    let h = Vector3::new(f.x, f.y, 0.0);
    if h.norm() > 1e-6 { h.normalize() } else { Vector3::x() }
}

fn rot_yaw_pitch(yaw: f64, pitch: f64) -> Rotation3<f64> {
    // Pitch up turns +x towards +z: a rotation about -y.
    Rotation3::from_axis_angle(&Vector3::z_axis(), yaw) * Rotation3::from_axis_angle(&Vector3::y_axis(), -pitch)
}

/// A pose being built: each joint's position and frame, in the mouse frame.
struct Posing {
    joints: JointPositions,
    frames: [Rotation3<f64>; crate::core::skeleton::JOINT_COUNT],
}

impl Posing {
    fn set(&mut self, j: Joint, p: Point3<f64>, r: Rotation3<f64>) {
        self.joints[j.index()] = p;
        self.frames[j.index()] = r;
    }

    fn at(&self, j: Joint) -> Point3<f64> {
        self.joints[j.index()]
    }

    fn frame(&self, j: Joint) -> Rotation3<f64> {
        self.frames[j.index()]
    }
}

/// Poses the mouse: forward kinematics in the mouse frame, then the placement into the world.
pub fn pose_mouse(params: &PoseParams, placement: &Placement) -> MouseInstance {
    // The placement's pitch and roll tilt the body; the paws stay planted and the legs
    // follow by inverse kinematics, so the mouse still stands on the glass.
    let params = &PoseParams {
        trunk_pitch: params.trunk_pitch + placement.pitch,
        roll: params.roll + placement.roll,
        ..*params
    };
    let b = placement.bones.scaled(placement.scale);
    let s = placement.scale;
    let mut posing = Posing {
        joints: [Point3::origin(); crate::core::skeleton::JOINT_COUNT],
        frames: [Rotation3::identity(); crate::core::skeleton::JOINT_COUNT],
    };
    let rump = Point3::new(0.0, 0.0, params.rump_height * s * placement.stature);
    pose_spine(&mut posing, params, &b, s, rump);
    let tail = pose_tail(&mut posing, params, &b, s, rump);

    // Ears on the head, hips on the rump.
    let head = posing.at(Joint::Head);
    let head_frame = posing.frame(Joint::Head);
    let rump_frame = posing.frame(Joint::Rump);
    for (joint, side) in [(Joint::LeftEar, Side::Left), (Joint::RightEar, Side::Right)] {
        let p = head + head_frame * Vector3::new(-b.ear_back, side.sign() * b.ear_side, b.ear_up);
        posing.set(joint, p, head_frame);
    }
    for (joint, side) in [(Joint::LeftHip, Side::Left), (Joint::RightHip, Side::Right)] {
        let p = rump + rump_frame * Vector3::new(0.0, side.sign() * b.hip_side, -b.hip_down);
        posing.set(joint, p, rump_frame);
    }
    let withers = posing.at(Joint::Withers);
    let withers_frame = posing.frame(Joint::Withers);
    let shoulders = [Side::Left, Side::Right].map(|side| {
        withers + withers_frame * Vector3::new(b.shoulder_forward, side.sign() * b.shoulder_side, -b.shoulder_down)
    });
    pose_limbs(&mut posing, params, &b, s, &shoulders);

    place(
        MouseInstance {
            joints: posing.joints,
            frames: posing.frames,
            tail,
            shoulders,
            scale: s,
            girth: placement.girth,
            stature: placement.stature,
            behaviour: params.behaviour,
        },
        placement,
    )
}

/// Spine, from the `rump` forward. The head may not dip into the glass: it is lifted (less
/// head pitch) until the snout clears.
fn pose_spine(posing: &mut Posing, params: &PoseParams, b: &BoneLengths, s: f64, rump: Point3<f64>) {
    let body_roll = Rotation3::from_axis_angle(&Vector3::x_axis(), -params.roll);
    let chain = [
        (Joint::MidBack, b.mid_back_rump),
        (Joint::Withers, b.withers_mid_back),
        (Joint::Neck, b.neck_withers),
        (Joint::Head, b.head_neck),
        (Joint::Snout, b.snout_head),
    ];
    let mut pitch = params.pitch;
    for _ in 0..40 {
        let mut q = body_roll * rot_yaw_pitch(0.0, params.trunk_pitch);
        posing.set(Joint::Rump, rump, q);
        let mut p = rump;
        for (k, (joint, len)) in chain.into_iter().enumerate() {
            q *= rot_yaw_pitch(params.yaw[k], pitch[k]);
            p += q * Vector3::new(len, 0.0, 0.0);
            posing.set(joint, p, q);
        }
        if posing.at(Joint::Snout).z >= 5.0 * s && posing.at(Joint::Head).z >= 8.0 * s {
            break;
        }
        pitch[2] += 0.03;
        pitch[3] += 0.05;
        pitch[4] += 0.05;
    }
    // The head's frame is that of the muzzle (head to snout).
    posing.frames[Joint::Head.index()] = posing.frame(Joint::Snout);
}

/// The tail's base straight back from the `rump`, dropping towards the floor, and the tail
/// from it: an arc of constant curvature lying on the floor, lifted near its base. Returns
/// the tail's points.
fn pose_tail(
    posing: &mut Posing,
    params: &PoseParams,
    b: &BoneLengths,
    s: f64,
    rump: Point3<f64>,
) -> [Point3<f64>; TAIL_POINTS] {
    let rump_frame = posing.frame(Joint::Rump);
    let back_flat = flat_heading(&rump_frame);
    let back_dir = Rotation3::from_axis_angle(&Vector3::z_axis(), params.tail_yaw * 0.5) * -back_flat;
    let tail_base_height = (params.tail_lift + 4.0 * s).max(2.5 * s);
    let drop = (rump.z - tail_base_height).clamp(-b.rump_tail_base * 0.9, b.rump_tail_base * 0.9);
    let run = (b.rump_tail_base.powi(2) - drop.powi(2)).max(0.0).sqrt();
    let tail_base = rump + back_dir * run - Vector3::z() * drop;
    let tail_heading = back_dir.y.atan2(back_dir.x) + params.tail_yaw * 0.5;
    posing.set(Joint::TailBase, tail_base, rot_yaw_pitch(tail_heading + PI, 0.0));

    let mut tail = [tail_base; TAIL_POINTS];
    let seg = b.tail / (TAIL_POINTS - 1) as f64;
    let mut heading = tail_heading;
    let radius_tip = 0.8 * s;
    for i in 1..TAIL_POINTS {
        heading += params.tail_curl / (TAIL_POINTS - 1) as f64;
        let prev = tail[i - 1];
        let t = i as f64 / (TAIL_POINTS - 1) as f64;
        let z = radius_tip + (tail_base.z - radius_tip) * (1.0 - t).powi(2);
        let dz = z - prev.z;
        let horizontal = (seg * seg - dz * dz).max(0.0).sqrt();
        tail[i] = Point3::new(
            prev.x + horizontal * heading.cos(),
            prev.y + horizontal * heading.sin(),
            z,
        );
    }
    posing.set(Joint::TailTip, tail[TAIL_POINTS - 1], rot_yaw_pitch(heading + PI, 0.0));
    tail
}

/// Limbs: paws at their stance points plus offsets (fore paws raised towards the chest and
/// the face), then inverse kinematics from the `shoulders` and the hips.
fn pose_limbs(posing: &mut Posing, params: &PoseParams, b: &BoneLengths, s: f64, shoulders: &[Point3<f64>; 2]) {
    let snout = posing.at(Joint::Snout);
    let head_frame = posing.frame(Joint::Head);
    let withers_frame = posing.frame(Joint::Withers);
    let rump_frame = posing.frame(Joint::Rump);
    for (k, limb) in LIMBS.iter().enumerate() {
        let [dx, dy, dz] = params.paw_offsets[k];
        let sign = limb.side.sign();
        let (root, fwd) = if limb.fore {
            (
                shoulders[usize::from(limb.side == Side::Right)],
                flat_heading(&withers_frame),
            )
        } else {
            (posing.at(limb.root), flat_heading(&rump_frame))
        };
        let left = Vector3::z().cross(&fwd);
        let lengths = limb.lengths_in(b);
        let mut paw = stance_paw(&root, &fwd, sign, limb.fore, s, PAW_SOLE_MM)
            + fwd * dx * s
            + left * sign * dy * s
            + Vector3::z() * dz.max(0.0) * s;
        if limb.fore && (params.fore_raise > 0.0 || params.fore_to_face > 0.0) {
            let chest = chest_paw(&root, &withers_frame, sign, s);
            let face = face_paw(&snout, &head_frame, sign, s);
            let raised = paw + (chest - paw) * params.fore_raise.clamp(0.0, 1.0);
            paw = raised + (face - raised) * params.fore_to_face.clamp(0.0, 1.0);
            paw.z = paw.z.max(PAW_SOLE_MM * s);
        }
        let (upper, lower) = if limb.fore {
            fore_limb(&root, &paw, lengths, &fwd, &Vector3::z())
        } else {
            hind_limb(&root, &paw, lengths, params.ankle_angle, &fwd, &Vector3::z())
        };
        let limb_frame = if limb.fore { withers_frame } else { rump_frame };
        posing.set(limb.upper, upper, limb_frame);
        posing.set(limb.lower, lower, limb_frame);
        posing.set(limb.paw, paw, limb_frame);
    }
}

impl crate::core::skeleton::LimbChain {
    /// The limb's three bone lengths from `bones`.
    pub fn lengths_in(&self, bones: &BoneLengths) -> [f64; 3] {
        bones.limb(self.fore)
    }
}

/// Moves a mouse built in its own frame into the world: turn to the heading, translate, and
/// set it on the floor.
fn place(mut m: MouseInstance, placement: &Placement) -> MouseInstance {
    let r = Rotation3::from_axis_angle(&Vector3::z_axis(), placement.heading);
    let world_from_mouse = Isometry3::from_parts(
        Translation3::new(placement.x_mm, placement.y_mm, 0.0),
        UnitQuaternion::from_rotation_matrix(&r),
    );
    let mut map = |p: &mut Point3<f64>| *p = world_from_mouse * *p;
    m.joints.iter_mut().for_each(&mut map);
    m.tail.iter_mut().for_each(&mut map);
    m.shoulders.iter_mut().for_each(&mut map);
    for f in &mut m.frames {
        *f = r * *f;
    }
    // Set the lowest paw (or tail point) on the glass.
    // Paws rest on their soles, the tail on its thinnest radius; no other joint may sink below
    // the skin of a leg (about 1.5 mm).
    let lowest = Joint::ALL
        .iter()
        .filter(|j| j.group() != crate::core::skeleton::JointGroup::Tail)
        .map(|j| m.joints[j.index()].z - PAW_SOLE_MM * m.scale)
        .chain(m.tail.iter().map(|p| p.z - 0.8 * m.scale))
        .fold(f64::INFINITY, f64::min);
    let lift = -lowest;
    let mut raise = |p: &mut Point3<f64>| p.z += lift;
    m.joints.iter_mut().for_each(&mut raise);
    m.tail.iter_mut().for_each(&mut raise);
    m.shoulders.iter_mut().for_each(&mut raise);
    m
}

/// Gait: the stance/swing offsets of the four paws at a phase of the cycle.
///
/// `pair_phase` gives each limb's phase shift (left fore, right fore, left hind, right hind).
fn gait(phase: f64, stride: f64, lift: f64, pair_phase: [f64; 4], duty: f64) -> [[f64; 3]; 4] {
    let mut out = [[0.0; 3]; 4];
    for (k, shift) in pair_phase.into_iter().enumerate() {
        let p = (phase + shift).rem_euclid(1.0);
        if p < duty {
            // Stance: the paw moves back under the body.
            let t = p / duty;
            out[k] = [stride * (0.5 - t), 0.0, 0.0];
        } else {
            let t = (p - duty) / (1.0 - duty);
            out[k] = [stride * (t - 0.5), 0.0, lift * (PI * t).sin()];
        }
    }
    out
}

/// Trot-like walk: diagonal pairs move together.
pub const WALK_PHASES: [f64; 4] = [0.0, 0.5, 0.5, 0.0];
/// Bound: fore pair and hind pair move together, half a cycle apart.
pub const RUN_PHASES: [f64; 4] = [0.0, 0.08, 0.5, 0.58];

/// The pose parameters of one behaviour, from a few shape controls in `[-1, 1]` or `[0, 1]`.
///
/// `phase` is the gait or activity cycle in `[0, 1)`, `bend` the lateral bend (-1 right, 1
/// left), `head` the head's yaw and `look` its pitch (both -1..1), `amount` the behaviour's
/// strength (how fast, how high, how tight) in `[0, 1]`.
pub fn behaviour_params(behaviour: Behaviour, phase: f64, bend: f64, head: f64, look: f64, amount: f64) -> PoseParams {
    let mut p = PoseParams {
        behaviour,
        ..PoseParams::default()
    };
    let spread = |bend: f64, weights: [f64; 5]| weights.map(|w| w * bend);
    p.yaw = spread(bend * 0.22, [0.6, 1.0, 1.0, 0.5, 0.2]);
    p.yaw[3] += head * 0.45;
    p.yaw[4] += head * 0.2;
    p.pitch[3] += look * 0.3;
    p.pitch[4] += look * 0.2;
    p.tail_yaw = -bend * 0.5 + 0.3 * (TAU * phase).sin();
    p.tail_curl = -bend * 0.9 + 0.6 * (TAU * (phase + 0.3)).sin();
    let cycle = (TAU * phase).sin();
    match behaviour {
        Behaviour::Stand => {
            p.paw_offsets = [[1.0, 0.0, 0.0], [-1.0, 0.5, 0.0], [0.5, 0.0, 0.0], [-0.5, 0.5, 0.0]]
                .map(|[x, y, z]| [x * cycle, y, z]);
            p.rump_height = 15.0 + 1.5 * amount;
        }
        Behaviour::Walk => {
            p.paw_offsets = gait(phase, 14.0 + 14.0 * amount, 4.0, WALK_PHASES, 0.6);
            p.yaw[1] += 0.05 * cycle;
            p.roll = 0.05 * cycle;
            p.rump_height = 16.5;
        }
        Behaviour::Run => {
            p.paw_offsets = gait(phase, 28.0 + 22.0 * amount, 7.0, RUN_PHASES, 0.4);
            // The back flexes and extends with the bound.
            p.pitch[0] += 0.12 * cycle;
            p.pitch[1] -= 0.10 * cycle;
            p.trunk_pitch = 0.02 + 0.05 * cycle;
            p.rump_height = 17.5 + 2.0 * (TAU * phase).cos();
            p.tail_lift = 8.0;
        }
        Behaviour::Turn => {
            p.yaw = spread(bend * 0.42, [0.7, 1.0, 1.0, 0.7, 0.3]);
            p.yaw[3] += head * 0.3;
            p.paw_offsets = gait(phase, 10.0 + 6.0 * amount, 3.0, WALK_PHASES, 0.65);
            let side = bend.signum();
            // Paws step towards the inside of the turn.
            for (k, off) in p.paw_offsets.iter_mut().enumerate() {
                let outward = if k % 2 == 0 { 1.0 } else { -1.0 };
                off[1] += 2.0 * side * outward * amount;
            }
        }
        Behaviour::Bend => {
            p.yaw = spread(bend * (0.35 + 0.25 * amount), [0.8, 1.0, 0.9, 0.8, 0.4]);
            p.yaw[3] += head * 0.3;
            p.roll = 0.1 * bend;
            p.rump_height = 14.5 + 2.5 * amount;
        }
        Behaviour::Rear => {
            p.trunk_pitch = 0.55 + 0.75 * amount;
            p.pitch = [
                -0.1 * amount,
                -0.15,
                -0.25 - 0.2 * amount,
                -0.3 + look * 0.35,
                -0.35 + look * 0.25,
            ];
            p.rump_height = 11.0;
            p.fore_raise = 0.55 + 0.45 * amount;
            p.paw_offsets[2] = [6.0, 1.0, 0.0];
            p.paw_offsets[3] = [6.0, 1.0, 0.0];
            p.paw_offsets[0][0] = 3.0 * cycle;
            p.paw_offsets[1][0] = -3.0 * cycle;
            p.tail_lift = 0.0;
        }
        Behaviour::Groom => {
            p.trunk_pitch = 0.75 + 0.35 * amount;
            p.pitch = [0.0, -0.1, -0.3, -0.45 + 0.2 * look, -0.4];
            p.rump_height = 12.0;
            p.fore_raise = 0.7;
            p.fore_to_face = 0.6 + 0.4 * (0.5 + 0.5 * cycle);
            p.paw_offsets[2] = [5.0, 1.0, 0.0];
            p.paw_offsets[3] = [5.0, 1.0, 0.0];
            p.tail_lift = 0.0;
        }
        Behaviour::Sniff => {
            // Head down to the floor, back arched.
            p.pitch = [0.14, -0.20, -0.26 - 0.2 * amount, -0.4 + 0.2 * look, -0.3];
            p.rump_height = 16.0 + 1.5 * amount;
            p.paw_offsets[0][0] = 2.0 * cycle;
            p.paw_offsets[1][0] = -2.0 * cycle;
        }
    }
    p
}

/// The procedural pose library: a deterministic grid over behaviour, cycle phase, bend, head
/// direction and strength, at least 800 distinct poses (see [`pose_library`]).
pub fn pose_library() -> Vec<PoseParams> {
    let mut out = Vec::new();
    let phases = |n: usize| (0..n).map(move |i| i as f64 / n as f64);
    for behaviour in Behaviour::ALL {
        match behaviour {
            Behaviour::Walk | Behaviour::Run => {
                for phase in phases(16) {
                    for bend in [-0.6, -0.25, 0.0, 0.25, 0.6] {
                        for amount in [0.2, 0.8] {
                            let head = bend * 0.5;
                            out.push(behaviour_params(behaviour, phase, bend, head, 0.0, amount));
                        }
                    }
                }
            }
            Behaviour::Turn => {
                for phase in phases(8) {
                    for bend in [-1.0, -0.7, -0.4, 0.4, 0.7, 1.0] {
                        for amount in [0.3, 0.9] {
                            out.push(behaviour_params(behaviour, phase, bend, bend * 0.8, 0.0, amount));
                        }
                    }
                }
            }
            Behaviour::Stand | Behaviour::Bend | Behaviour::Sniff => {
                for bend in [-1.0, -0.5, 0.0, 0.5, 1.0] {
                    for head in [-1.0, -0.3, 0.3, 1.0] {
                        for look in [-0.8, 0.0, 0.8] {
                            for amount in [0.2, 0.9] {
                                let phase: f64 = (bend + head + look) * 0.37;
                                out.push(behaviour_params(
                                    behaviour,
                                    phase.rem_euclid(1.0),
                                    bend,
                                    head,
                                    look,
                                    amount,
                                ));
                            }
                        }
                    }
                }
            }
            Behaviour::Rear | Behaviour::Groom => {
                for phase in phases(4) {
                    for head in [-1.0, -0.4, 0.4, 1.0] {
                        for look in [-0.6, 0.6] {
                            for amount in [0.0, 0.5, 1.0] {
                                out.push(behaviour_params(behaviour, phase, head * 0.3, head, look, amount));
                            }
                        }
                    }
                }
            }
        }
    }
    out
}

impl PoseParams {
    /// The parameters a fraction `t` of the way from `self` to `other` (behaviour switches at
    /// the half-way point).
    pub fn lerp(&self, other: &PoseParams, t: f64) -> PoseParams {
        let l = |a: f64, b: f64| a + (b - a) * t;
        let la = |a: &[f64; SPINE_SEGMENTS], b: &[f64; SPINE_SEGMENTS]| std::array::from_fn(|k| l(a[k], b[k]));
        PoseParams {
            behaviour: if t < 0.5 { self.behaviour } else { other.behaviour },
            rump_height: l(self.rump_height, other.rump_height),
            trunk_pitch: l(self.trunk_pitch, other.trunk_pitch),
            yaw: la(&self.yaw, &other.yaw),
            pitch: la(&self.pitch, &other.pitch),
            roll: l(self.roll, other.roll),
            tail_yaw: l(self.tail_yaw, other.tail_yaw),
            tail_curl: l(self.tail_curl, other.tail_curl),
            tail_lift: l(self.tail_lift, other.tail_lift),
            paw_offsets: std::array::from_fn(|k| {
                std::array::from_fn(|c| l(self.paw_offsets[k][c], other.paw_offsets[k][c]))
            }),
            fore_raise: l(self.fore_raise, other.fore_raise),
            fore_to_face: l(self.fore_to_face, other.fore_to_face),
            ankle_angle: l(self.ankle_angle, other.ankle_angle),
        }
    }
}

/// Shifts a posed mouse horizontally so that every joint and tail point lies at least
/// `margin_mm` inside the cage's walls (no part of the mouse passes through a wall).
pub fn fit_in_cage(m: &mut MouseInstance, margin_mm: f64) {
    use crate::core::geometry::{CAGE_X_MM, CAGE_Y_MM};
    let points = || m.joints.iter().chain(m.tail.iter());
    let mut shift = [0.0f64; 2];
    for (axis, half) in [(0usize, CAGE_X_MM / 2.0 - margin_mm), (1, CAGE_Y_MM / 2.0 - margin_mm)] {
        let lo = points().map(|p| p[axis]).fold(f64::INFINITY, f64::min);
        let hi = points().map(|p| p[axis]).fold(f64::NEG_INFINITY, f64::max);
        shift[axis] = if hi - lo > 2.0 * half {
            -(hi + lo) / 2.0
        } else if hi > half {
            half - hi
        } else if lo < -half {
            -half - lo
        } else {
            0.0
        };
    }
    let v = Vector3::new(shift[0], shift[1], 0.0);
    m.joints.iter_mut().for_each(|p| *p += v);
    m.tail.iter_mut().for_each(|p| *p += v);
    m.shoulders.iter_mut().for_each(|p| *p += v);
}
