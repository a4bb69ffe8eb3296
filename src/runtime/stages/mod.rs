//! The processing stages of the pipeline, one per file, and the items that travel between
//! them. Each is a plain object with a `process` function the runner calls on its own thread
//! and a unit test can call directly, and declares what it takes, what it gives and its name
//! (`pipeline::Map`: one output per input; the synchroniser, a `pipeline::FlatMap`). The order
//! of the stages is declared in `topology::declare_processing`.

pub mod body;
pub mod fuse;
pub mod overlay;
pub mod paws;
pub mod segment;
pub mod sync;

use crate::core::frame::FramePair;
use crate::core::pose::Pose;
use crate::vision::segment::Mouse;

/// A frame pair and the mouse found in its depth frame (`None`: no mouse).
#[derive(Debug)]
pub struct Segmented {
    pub pair: FramePair,
    pub mouse: Option<Mouse>,
    /// False while a live run has no background model yet (no floor in view).
    pub background: bool,
}

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
}

/// A frame pair and its pose so far, on its way through the stages that add to the pose.
#[derive(Debug)]
pub struct Posed {
    pub pair: FramePair,
    pub record: PoseRecord,
}

/// The finished pose of a frame pair, its frames (shared, for the live view) and its
/// picture when one was asked for.
#[derive(Debug)]
pub struct Fused {
    pub record: PoseRecord,
    pub frames: FramePair,
    pub overlay: Option<crate::core::image::RgbImage>,
}
