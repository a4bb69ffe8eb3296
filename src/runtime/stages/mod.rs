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
use crate::runtime::pose_record::PoseRecord;
use crate::vision::segment::Mouse;

/// A frame pair and the mouse found in its depth frame (`None`: no mouse).
#[derive(Debug)]
pub struct Segmented {
    pub pair: FramePair,
    pub mouse: Option<Mouse>,
    /// False while a live run has no background model yet (no floor in view).
    pub background: bool,
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
