//! The segmentation stage: finds the mouse in each depth frame, and refreshes the background
//! model with frames where there is none.

use super::Segmented;
use crate::core::frame::FramePair;
use crate::runtime::pipeline::{Stage, StageError};
use crate::vision::segment::Segmenter;

/// Runs a [`Segmenter`] on each pair's depth frame.
#[derive(Debug)]
pub struct SegmentStage {
    segmenter: Segmenter,
}

impl SegmentStage {
    pub fn new(segmenter: Segmenter) -> Self {
        Self { segmenter }
    }
}

impl Stage for SegmentStage {
    type In = FramePair;
    type Out = Segmented;

    fn process(&mut self, pair: FramePair, out: &mut Vec<Segmented>) -> Result<(), StageError> {
        let mouse = self.segmenter.segment(&pair.depth)?;
        if mouse.is_none() {
            self.segmenter.update_background(&pair.depth, false)?;
        }
        out.push(Segmented { pair, mouse });
        Ok(())
    }
}
