//! The fusion stage: the head's end chosen by the orientation tracker (see
//! [`crate::vision::orientation`]), the main-body joints smoothed over time (see
//! [`crate::vision::smoothing`]; the frame's own kept beside them), paws and limbs added to the body's joints (see
//! [`crate::vision::fusion`]), and the picture of every n-th frame. It carries the tracker's
//! and the legs' memory from frame to frame, so the runner gives it its frames in order.

use super::{Fused, Posed};
use crate::core::geometry::Rig;
use crate::core::skeleton::Joint;
use crate::runtime::overlay;
use crate::runtime::pipeline::{Map, StageError};
use crate::runtime::pose_record::{PoseRecord, PoseStatus};
use crate::vision::fusion::Fuser;
use crate::vision::orientation::{self, BodyJoints, Orientation, Tracker, TrackerConfig};
use crate::vision::smoothing::{Smoother, SmootherConfig};

/// Runs a [`Fuser`] on each pose.
#[derive(Debug, Clone)]
pub struct FuseStage {
    /// Mouse 1's memory (the only mouse's, with one).
    first: MouseMemory,
    /// With several mice, those of mice 2.. (made as they first come).
    others: Vec<MouseMemory>,
    rig: Rig,
    /// Draw a picture of the frames whose depth sequence number is a multiple of this.
    overlay_every: Option<u64>,
}

/// What the stage remembers of one mouse from frame to frame: its legs, which end is its
/// head, and its joints' motion.
#[derive(Debug, Clone)]
struct MouseMemory {
    fuser: Fuser,
    tracker: Tracker,
    smoother: Smoother,
}

impl FuseStage {
    pub fn new(fuser: Fuser, rig: Rig, overlay_every: Option<u64>) -> Self {
        Self {
            first: MouseMemory {
                fuser,
                tracker: Tracker::new(TrackerConfig::default()),
                smoother: Smoother::new(SmootherConfig::default()),
            },
            others: Vec::new(),
            rig,
            overlay_every: overlay_every.filter(|&n| n > 0),
        }
    }
}

impl MouseMemory {
    /// Finishes the pose of `record` (see the module documentation); `color`: whether its
    /// pair has a colour frame.
    fn finish(&mut self, record: &mut PoseRecord, color: bool) {
        if let Some(headings) = record.headings.take() {
            let decision = self.tracker.update(record.depth.device_ns, &headings);
            let raw = headings.joints[decision.chosen];
            let mut smoothed: BodyJoints = raw;
            self.smoother
                .smooth(record.depth.device_ns, &mut smoothed, &headings.body);
            for (joint, estimate) in Joint::MAIN_BODY.iter().zip(smoothed) {
                *record.pose.joint_mut(*joint) = estimate;
            }
            record.raw_body = Some(Box::new(raw));
            record.velocities = Some(Box::new(self.smoother.velocities()));
            record.orientation = Some(Orientation {
                confidence: decision.confidence,
                frame_alone: orientation::heading(&headings.joints[decision.frame_alone]),
                forest: headings.forest_heading,
                shape: (headings.shape != 0.0)
                    .then(|| orientation::heading(&headings.joints[usize::from(headings.shape < 0.0)]))
                    .flatten(),
                tail: (headings.tail != 0.0)
                    .then(|| orientation::heading(&headings.joints[usize::from(headings.tail < 0.0)]))
                    .flatten(),
            });
        }
        if record.orientation.is_none() {
            self.smoother.reset();
        }
        // Depth-only pairs keep joints 1-12 (the paper's single depth image mode).
        if record.status == PoseStatus::Ok && color {
            self.fuser.fuse(record.depth.seq, &mut record.pose, &record.paws);
        }
    }

    /// The memory of a mouse not seen before, as `self` was made.
    fn fresh(&self) -> Self {
        Self {
            fuser: self.fuser.fresh(),
            tracker: Tracker::new(TrackerConfig::default()),
            smoother: Smoother::new(SmootherConfig::default()),
        }
    }
}

impl Map for FuseStage {
    type In = Posed;
    type Out = Fused;
    const NAME: &'static str = "fuse";

    fn process(&mut self, input: Posed) -> Result<Fused, StageError> {
        let Posed {
            pair,
            mut record,
            mut others,
        } = input;
        let color = pair.color.is_some();
        self.first.finish(&mut record, color);
        while self.others.len() < others.len() {
            self.others.push(self.first.fresh());
        }
        for (memory, record) in self.others.iter_mut().zip(&mut others) {
            memory.finish(record, color);
        }
        let overlay = self
            .overlay_every
            .filter(|n| record.depth.seq % n == 0)
            .map(|_| overlay::draw(&self.rig, &pair.depth, pair.color.as_deref(), &record));
        Ok(Fused {
            record,
            others,
            frames: pair,
            overlay,
        })
    }
}
