//! Step 2 of the paper: the paws in the bottom colour view, found by a boosted cascade of
//! Haar-like features (Viola-Jones) stored in OpenCV's cascade XML.

use serde::{Deserialize, Serialize};

/// One paw found in a bottom colour frame.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PawDetection {
    /// Box in the full colour frame's pixel coordinates.
    pub x0: f32,
    pub y0: f32,
    pub x1: f32,
    pub y1: f32,
    /// The detector's confidence: higher is surer; comparable between detections of one model.
    pub score: f32,
}

impl PawDetection {
    /// The box's centre, in the colour frame's pixel coordinates.
    pub fn centre(&self) -> (f64, f64) {
        (f64::from(self.x0 + self.x1) / 2.0, f64::from(self.y0 + self.y1) / 2.0)
    }
}
