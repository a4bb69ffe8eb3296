//! The mouse model: 24 joints with the paper's numbering, the bones that
//! join them, the limb chains, the six body-part labels, and the bone lengths of an adult mouse
//! (about 100 mm from snout to tail base).
//!
//! Joint names are a contract: pose files, JSON reports and every downstream script use them.

use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// Version of the joint table and part labels; stored in every model and data file.
pub const SKELETON_VERSION: u32 = 1;

/// Number of joints in the model.
pub const JOINT_COUNT: usize = 24;

/// The joints, in the paper's order (`Joint::Snout.number() == 1`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum Joint {
    Snout,
    Head,
    Neck,
    Withers,
    MidBack,
    Rump,
    TailBase,
    TailTip,
    LeftEar,
    RightEar,
    LeftHip,
    RightHip,
    LeftElbow,
    LeftWrist,
    RightElbow,
    RightWrist,
    LeftKnee,
    LeftAnkle,
    RightKnee,
    RightAnkle,
    LeftForePaw,
    RightForePaw,
    LeftHindPaw,
    RightHindPaw,
}

/// Where a joint's group sits in the model (and which colour draws it).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JointGroup {
    Spine,
    Tail,
    Ear,
    MainBody,
    ForeLimb,
    HindLimb,
    Paw,
}

impl Joint {
    pub const ALL: [Joint; JOINT_COUNT] = [
        Joint::Snout,
        Joint::Head,
        Joint::Neck,
        Joint::Withers,
        Joint::MidBack,
        Joint::Rump,
        Joint::TailBase,
        Joint::TailTip,
        Joint::LeftEar,
        Joint::RightEar,
        Joint::LeftHip,
        Joint::RightHip,
        Joint::LeftElbow,
        Joint::LeftWrist,
        Joint::RightElbow,
        Joint::RightWrist,
        Joint::LeftKnee,
        Joint::LeftAnkle,
        Joint::RightKnee,
        Joint::RightAnkle,
        Joint::LeftForePaw,
        Joint::RightForePaw,
        Joint::LeftHindPaw,
        Joint::RightHindPaw,
    ];

    /// The twelve main-body joints the top depth camera sees (step 1).
    pub const MAIN_BODY: [Joint; 12] = [
        Joint::Snout,
        Joint::Head,
        Joint::Neck,
        Joint::Withers,
        Joint::MidBack,
        Joint::Rump,
        Joint::TailBase,
        Joint::TailTip,
        Joint::LeftEar,
        Joint::RightEar,
        Joint::LeftHip,
        Joint::RightHip,
    ];

    /// The four paws the bottom colour camera sees (step 2), in joint order.
    pub const PAWS: [Joint; 4] = [
        Joint::LeftForePaw,
        Joint::RightForePaw,
        Joint::LeftHindPaw,
        Joint::RightHindPaw,
    ];

    /// Zero-based index into arrays of joints.
    pub fn index(self) -> usize {
        self as usize
    }

    /// The paper's one-based joint number.
    pub fn number(self) -> usize {
        self as usize + 1
    }

    /// The joint with a zero-based index.
    pub fn from_index(index: usize) -> Option<Joint> {
        Self::ALL.get(index).copied()
    }

    /// The contract name: `snout`, `left_fore_paw`, ...
    pub fn name(self) -> &'static str {
        JOINT_NAMES[self.index()]
    }

    pub fn group(self) -> JointGroup {
        use Joint::*;
        match self {
            Snout | Head | Neck | Withers | MidBack | Rump => JointGroup::Spine,
            TailBase | TailTip => JointGroup::Tail,
            LeftEar | RightEar => JointGroup::Ear,
            LeftHip | RightHip => JointGroup::MainBody,
            LeftElbow | LeftWrist | RightElbow | RightWrist => JointGroup::ForeLimb,
            LeftKnee | LeftAnkle | RightKnee | RightAnkle => JointGroup::HindLimb,
            LeftForePaw | RightForePaw | LeftHindPaw | RightHindPaw => JointGroup::Paw,
        }
    }

    /// The paper's epsilon: how close (mm) a training pixel must be to this joint to vote for
    /// it (10 paws, 15 limbs and ears, 50 tail, 25 the rest).
    pub fn vote_radius_mm(self) -> f64 {
        match self.group() {
            JointGroup::Paw => 10.0,
            JointGroup::ForeLimb | JointGroup::HindLimb | JointGroup::Ear => 15.0,
            JointGroup::Tail => 50.0,
            JointGroup::Spine | JointGroup::MainBody => 25.0,
        }
    }
}

const JOINT_NAMES: [&str; JOINT_COUNT] = [
    "snout",
    "head",
    "neck",
    "withers",
    "mid_back",
    "rump",
    "tail_base",
    "tail_tip",
    "left_ear",
    "right_ear",
    "left_hip",
    "right_hip",
    "left_elbow",
    "left_wrist",
    "right_elbow",
    "right_wrist",
    "left_knee",
    "left_ankle",
    "right_knee",
    "right_ankle",
    "left_fore_paw",
    "right_fore_paw",
    "left_hind_paw",
    "right_hind_paw",
];

impl fmt::Display for Joint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A joint name that is not in the joint table.
#[derive(Debug, thiserror::Error)]
#[error("unknown joint name {0:?}")]
pub struct UnknownJoint(pub String);

impl FromStr for Joint {
    type Err = UnknownJoint;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        JOINT_NAMES
            .iter()
            .position(|&n| n == s)
            .and_then(Joint::from_index)
            .ok_or_else(|| UnknownJoint(s.to_owned()))
    }
}

/// How a bone is drawn (the paper's colours: spine red, ears green, limbs blue).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BoneKind {
    Spine,
    Ear,
    Limb,
}

/// The bones of the model as joint pairs. Fore limbs hang from `withers` (the shoulder is an
/// offset from it), hind limbs from the hips.
pub const BONES: [(Joint, Joint, BoneKind); 23] = {
    use BoneKind::*;
    use Joint::*;
    [
        (Snout, Head, Spine),
        (Head, Neck, Spine),
        (Neck, Withers, Spine),
        (Withers, MidBack, Spine),
        (MidBack, Rump, Spine),
        (Rump, TailBase, Spine),
        (TailBase, TailTip, Spine),
        (Head, LeftEar, Ear),
        (Head, RightEar, Ear),
        (Rump, LeftHip, Limb),
        (Rump, RightHip, Limb),
        (Withers, LeftElbow, Limb),
        (LeftElbow, LeftWrist, Limb),
        (LeftWrist, LeftForePaw, Limb),
        (Withers, RightElbow, Limb),
        (RightElbow, RightWrist, Limb),
        (RightWrist, RightForePaw, Limb),
        (LeftHip, LeftKnee, Limb),
        (LeftKnee, LeftAnkle, Limb),
        (LeftAnkle, LeftHindPaw, Limb),
        (RightHip, RightKnee, Limb),
        (RightKnee, RightAnkle, Limb),
        (RightAnkle, RightHindPaw, Limb),
    ]
};

/// Which side of the body a limb is on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Side {
    Left,
    Right,
}

impl Side {
    /// +1 for left (the mouse's +y in its own frame), -1 for right.
    pub fn sign(self) -> f64 {
        match self {
            Side::Left => 1.0,
            Side::Right => -1.0,
        }
    }
}

/// A limb: the chain from its root on the body to its paw.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LimbChain {
    pub side: Side,
    pub fore: bool,
    /// Elbow or knee.
    pub upper: Joint,
    /// Wrist or ankle.
    pub lower: Joint,
    pub paw: Joint,
    /// The body joint the limb hangs from: `withers` (via the shoulder offset) or the hip.
    pub root: Joint,
}

/// The four limbs: left fore, right fore, left hind, right hind.
pub const LIMBS: [LimbChain; 4] = [
    LimbChain {
        side: Side::Left,
        fore: true,
        upper: Joint::LeftElbow,
        lower: Joint::LeftWrist,
        paw: Joint::LeftForePaw,
        root: Joint::Withers,
    },
    LimbChain {
        side: Side::Right,
        fore: true,
        upper: Joint::RightElbow,
        lower: Joint::RightWrist,
        paw: Joint::RightForePaw,
        root: Joint::Withers,
    },
    LimbChain {
        side: Side::Left,
        fore: false,
        upper: Joint::LeftKnee,
        lower: Joint::LeftAnkle,
        paw: Joint::LeftHindPaw,
        root: Joint::LeftHip,
    },
    LimbChain {
        side: Side::Right,
        fore: false,
        upper: Joint::RightKnee,
        lower: Joint::RightAnkle,
        paw: Joint::RightHindPaw,
        root: Joint::RightHip,
    },
];

/// The six body-part labels of the paper's part-based labelling.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum Part {
    Head,
    FrontRight,
    FrontLeft,
    RearRight,
    RearLeft,
    Tail,
}

/// The label value of pixels that show no mouse.
pub const BACKGROUND_LABEL: u8 = 255;

/// Number of part classes.
pub const PART_COUNT: usize = 6;

impl Part {
    pub const ALL: [Part; PART_COUNT] = [
        Part::Head,
        Part::FrontRight,
        Part::FrontLeft,
        Part::RearRight,
        Part::RearLeft,
        Part::Tail,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Part::Head => "head",
            Part::FrontRight => "front_right",
            Part::FrontLeft => "front_left",
            Part::RearRight => "rear_right",
            Part::RearLeft => "rear_left",
            Part::Tail => "tail",
        }
    }

    /// The label byte stored in label images.
    pub fn label(self) -> u8 {
        self as u8
    }

    pub fn from_label(label: u8) -> Option<Part> {
        Self::ALL.get(usize::from(label)).copied()
    }

    /// The part of the trunk at a side and end of the body.
    pub fn trunk(front: bool, side: Side) -> Part {
        match (front, side) {
            (true, Side::Right) => Part::FrontRight,
            (true, Side::Left) => Part::FrontLeft,
            (false, Side::Right) => Part::RearRight,
            (false, Side::Left) => Part::RearLeft,
        }
    }

    /// The paper's display colour (head green, front-right blue, front-left yellow,
    /// rear-right pink, rear-left cyan, tail red).
    pub fn colour(self) -> [u8; 3] {
        match self {
            Part::Head => [40, 200, 60],
            Part::FrontRight => [50, 90, 230],
            Part::FrontLeft => [240, 220, 40],
            Part::RearRight => [230, 80, 200],
            Part::RearLeft => [40, 210, 220],
            Part::Tail => [220, 40, 40],
        }
    }
}

impl fmt::Display for Part {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Bone lengths and body proportions of one mouse, in millimetres.
///
/// The defaults describe an adult mouse of about 100 mm from snout to tail base; the synthesis
/// engine scales them and varies each by up to 10 %.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BoneLengths {
    pub snout_head: f64,
    pub head_neck: f64,
    pub neck_withers: f64,
    pub withers_mid_back: f64,
    pub mid_back_rump: f64,
    pub rump_tail_base: f64,
    pub tail: f64,
    /// Ear joint: behind the head joint, to the side, and up.
    pub ear_back: f64,
    pub ear_side: f64,
    pub ear_up: f64,
    /// Hip joint: to the side of the rump and below it.
    pub hip_side: f64,
    pub hip_down: f64,
    /// Shoulder (the fore limb's root): ahead of the withers, to the side, and below.
    pub shoulder_forward: f64,
    pub shoulder_side: f64,
    pub shoulder_down: f64,
    pub upper_arm: f64,
    pub forearm: f64,
    pub fore_paw: f64,
    pub thigh: f64,
    pub shin: f64,
    pub hind_foot: f64,
}

impl Default for BoneLengths {
    fn default() -> Self {
        Self {
            snout_head: 13.0,
            head_neck: 14.0,
            neck_withers: 14.0,
            withers_mid_back: 20.0,
            mid_back_rump: 20.0,
            rump_tail_base: 18.0,
            tail: 80.0,
            ear_back: 3.0,
            ear_side: 8.0,
            ear_up: 6.0,
            hip_side: 9.0,
            hip_down: 4.0,
            shoulder_forward: 2.0,
            shoulder_side: 7.0,
            shoulder_down: 8.0,
            upper_arm: 11.0,
            forearm: 12.0,
            fore_paw: 5.0,
            thigh: 15.0,
            shin: 17.0,
            hind_foot: 11.0,
        }
    }
}

impl BoneLengths {
    /// Snout to tail base along the spine.
    pub fn body_length(&self) -> f64 {
        self.snout_head
            + self.head_neck
            + self.neck_withers
            + self.withers_mid_back
            + self.mid_back_rump
            + self.rump_tail_base
    }

    /// Every length multiplied by `factor`.
    pub fn scaled(&self, factor: f64) -> Self {
        self.map(|v| v * factor)
    }

    /// Applies `f` to every length.
    pub fn map(&self, mut f: impl FnMut(f64) -> f64) -> Self {
        Self {
            snout_head: f(self.snout_head),
            head_neck: f(self.head_neck),
            neck_withers: f(self.neck_withers),
            withers_mid_back: f(self.withers_mid_back),
            mid_back_rump: f(self.mid_back_rump),
            rump_tail_base: f(self.rump_tail_base),
            tail: f(self.tail),
            ear_back: f(self.ear_back),
            ear_side: f(self.ear_side),
            ear_up: f(self.ear_up),
            hip_side: f(self.hip_side),
            hip_down: f(self.hip_down),
            shoulder_forward: f(self.shoulder_forward),
            shoulder_side: f(self.shoulder_side),
            shoulder_down: f(self.shoulder_down),
            upper_arm: f(self.upper_arm),
            forearm: f(self.forearm),
            fore_paw: f(self.fore_paw),
            thigh: f(self.thigh),
            shin: f(self.shin),
            hind_foot: f(self.hind_foot),
        }
    }

    /// The three bone lengths of a limb chain, root outward.
    pub fn limb(&self, fore: bool) -> [f64; 3] {
        if fore {
            [self.upper_arm, self.forearm, self.fore_paw]
        } else {
            [self.thigh, self.shin, self.hind_foot]
        }
    }
}
