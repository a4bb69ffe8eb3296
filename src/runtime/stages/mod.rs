//! The processing stages of the pipeline, one per file, and the items that travel between
//! them. Each is a plain object with a `process` function the runner calls on its own thread
//! and a unit test can call directly, and declares what it takes, what it gives and its name
//! (`pipeline::Map`: one output per input; the synchroniser, a `pipeline::FlatMap`). The order
//! of the stages is declared in `topology::declare_processing`.

pub mod body;
pub mod fuse;
pub mod paws;
pub mod segment;
pub mod sync;

use crate::core::frame::FramePair;
use crate::runtime::pose_record::{Identity, PoseRecord};
use crate::vision::segment::Mouse;

/// A frame pair and the mice found in its depth frame.
#[derive(Debug)]
pub struct Segmented {
    pub pair: FramePair,
    /// One entry with one mouse in the cage (`mouse`: `None` when none was found); with several
    /// (`[mice] count`), one per mouse in the order of their numbers, each with its identity.
    pub mice: Vec<Found>,
    /// False while a live run has no background model yet (no floor in view).
    pub background: bool,
}

/// One mouse of a frame, as segmentation found it.
#[derive(Debug)]
pub struct Found {
    pub mouse: Option<Mouse>,
    /// Which of several mice it is; `None` with one mouse.
    pub identity: Option<Identity>,
}

/// A frame pair and its pose so far, on its way through the stages that add to the pose.
#[derive(Debug)]
pub struct Posed {
    pub pair: FramePair,
    pub record: PoseRecord,
    /// With several mice, the poses of mice 2.. (`record` is mouse 1's); empty with one.
    pub others: Vec<PoseRecord>,
}

/// The finished pose of a frame pair, its frames (shared, for the live view) and its
/// picture when one was asked for.
#[derive(Debug)]
pub struct Fused {
    pub record: PoseRecord,
    /// With several mice, the poses of mice 2.. (`record` is mouse 1's); empty with one.
    pub others: Vec<PoseRecord>,
    pub frames: FramePair,
    pub overlay: Option<crate::core::image::RgbImage>,
}

impl Fused {
    /// Every mouse's pose, mouse 1's first.
    pub fn records(&self) -> impl Iterator<Item = &PoseRecord> {
        std::iter::once(&self.record).chain(&self.others)
    }
}
