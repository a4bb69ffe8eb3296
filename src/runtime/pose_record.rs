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
}
