//! What the pipeline gives for each frame pair, the product's output record: its status, the
//! 24 joints, the paws found and the orientation chosen, with both frames' stamps. The stages
//! fill it in; `poses.csv`, the chunks, the live status and the exports read it.

use crate::core::pose::Pose;

/// What the pipeline says of one frame pair.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PoseStatus {
    /// The mouse was found and its joints estimated.
    Ok,
    /// No mouse in the depth frame (an empty cage, or the mouse hidden).
    NoMouse,
    /// No empty-cage model yet: a live run whose depth view shows no floor so far.
    NoBackground,
}

impl PoseStatus {
    /// The value of the `status` column.
    pub fn name(self) -> &'static str {
        match self {
            PoseStatus::Ok => "ok",
            PoseStatus::NoMouse => "no_mouse",
            PoseStatus::NoBackground => "no_background",
        }
    }

    /// Every status.
    pub const ALL: [PoseStatus; 3] = [PoseStatus::Ok, PoseStatus::NoMouse, PoseStatus::NoBackground];

    /// The status a value of the `status` column stands for.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.name() == name)
    }
}

/// The pose of one frame pair, with the frames' metadata (the frames themselves are dropped
/// once the pose is known).
#[derive(Clone, Debug)]
pub struct PoseRecord {
    pub depth: crate::core::frame::Stamp,
    pub color: Option<crate::core::frame::Stamp>,
    pub skew_ns: i64,
    pub status: PoseStatus,
    pub pose: Pose,
    /// The paws found in the bottom view (empty without a colour frame or a paw model).
    pub paws: Vec<crate::vision::paws::PawDetection>,
    /// The main-body joints under both orientations, from the body stage until the fusion
    /// stage's tracker has chosen (then `None`).
    pub headings: Option<Box<crate::vision::orientation::Headings>>,
    /// What the tracker chose, for a frame with a mouse.
    pub orientation: Option<crate::vision::orientation::Orientation>,
    /// The main-body joints as the frame alone placed them, before the fusion stage smoothed
    /// them over time (see [`crate::vision::smoothing`]); `None` without a mouse.
    pub raw_body: Option<Box<crate::vision::orientation::BodyJoints>>,
    /// Each main-body joint's velocity (mm/s, world frame) as the smoothing follows it, in
    /// [`crate::core::skeleton::Joint::MAIN_BODY`]'s order (see
    /// [`crate::vision::smoothing::Smoother::velocities`]); `None` without a mouse.
    pub velocities: Option<Box<[Option<nalgebra::Vector3<f64>>; 12]>>,
    /// With several mice in the cage, which one this is; `None` with one mouse.
    pub identity: Option<Identity>,
}

/// Which of several mice a pose is of.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Identity {
    /// Its number, 1..N, kept from the first frame to the last.
    pub mouse: usize,
    /// How sure that number is in this frame (0-1; `identity_confidence`): 0 where it was not
    /// found.
    pub confidence: f64,
    /// The other mouse's number, when this frame could have swapped the two.
    pub swap_with: Option<usize>,
    /// Mouse-sized things the frame showed beyond the mice counted (the same in each mouse's
    /// record of the frame): more mice seen than there are.
    pub beyond: usize,
}

/// The longest lead a pose is predicted for (ms): past a second, a mouse's velocity says
/// nothing of where it is.
pub const MAX_LEAD_MS: f64 = 1000.0;

/// A prediction's lead of `ms` milliseconds, as nanoseconds: from 0 to [`MAX_LEAD_MS`].
///
/// # Errors
/// Another number, in one sentence.
pub fn lead_ns(ms: f64) -> Result<u64, String> {
    if !(0.0..=MAX_LEAD_MS).contains(&ms) {
        return Err(format!("a lead must be from 0 to {MAX_LEAD_MS} ms, not {ms}"));
    }
    Ok((ms * 1e6).round() as u64)
}

impl PoseRecord {
    /// The velocity of `joint` (mm/s), where the smoothing follows it: a main-body joint
    /// but the tail tip, in a frame with a mouse. Limbs and paws have none: a paw on the
    /// floor stands while the body passes over it.
    pub fn velocity(&self, joint: crate::core::skeleton::Joint) -> Option<nalgebra::Vector3<f64>> {
        let k = crate::core::skeleton::Joint::MAIN_BODY
            .iter()
            .position(|j| *j == joint)?;
        self.velocities.as_ref().and_then(|v| v[k])
    }

    /// The pose predicted `lead_s` seconds after the depth frame was taken: each joint with a
    /// [`velocity`](Self::velocity) moved on by it for that long, every other joint as placed.
    pub fn predicted(&self, lead_s: f64) -> Pose {
        let mut pose = self.pose.clone();
        let velocities = self.velocities.iter().flat_map(|v| v.iter());
        for (joint, v) in crate::core::skeleton::Joint::MAIN_BODY.iter().zip(velocities) {
            if let Some(v) = v {
                pose.joint_mut(*joint).position_mm += v * lead_s;
            }
        }
        pose
    }
}
